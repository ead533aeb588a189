"""CCSDS Navigation Data Messages: OEM out and back, TDM in and out (KVN and XML).

`common` (errors, epochs and time systems, frames, the NDM library), `oem` (ephemerides with
covariance), `tdm_reader` (a TDM as a stream of segments and observations), `tdm_in` (its
measurements as the core's), `tdm_out` (measurements written as a TDM).
"""
