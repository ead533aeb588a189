"""The field's files, read and written: element sets, sites, CCSDS messages, laser ranging.

TLE/3LE and CCSDS OMM element sets (`element_sets` reads a catalog file: `tle`, `omm`, and
the checks both pass, `element_set_checks`), the user's sites file (`sites`, YAML), CCSDS
OEM and TDM in KVN and XML (`ccsds`), and what their hostile-input checks share (a file
read within a bound on its size: `files`). Every reader streams its file, validates every
field and raises one line naming the file, the line and the field. Imports only the core
(and lxml, PyYAML, ccsds-ndm), never ROS.
"""
