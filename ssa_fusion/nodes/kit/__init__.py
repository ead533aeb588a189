"""What the seven nodes share.

The one base class (`base.SsaNode`), a parameter table declared as ROS parameters
(`node_parameters`), /diagnostics counts and DDS matches (`diagnostics`), messages held
until the clock reaches them (`clock_hold`), the node's process from start to exit code
(`process`), lockstep progress (`progress`), a catalog node's shard (`shards`), the estimate
publisher's memory (`memory`) and catalog_filter's unlabelled rows (`unlabelled`). It may
import `ros`, `params`, `formats` and `core`, never `sim`, `graphs`, `studies`,
`evaluation` or `apps`.
"""
