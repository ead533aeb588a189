"""The nodes' parameters, without ROS.

Every node's table of rows (`tables`: name, default, unit, scale to the core's unit, rule,
run-time flag, a short description), the defaults (`defaults`), the checks and rows the
tables share (`checks`, `shared`), the one SI <-> core conversion by the rows' scales
(`units`), the estimator settings as parameters and back (`settings`), a ROS params file
read offline (`params_file`) and docs/NODES.md's tables generated from the rows (`doc`). It
may import only `ssa_fusion.core` and `ssa_fusion.formats`, never rclpy or another ROS
package (test/test_layers.py), so that the apps read a params file without ROS; the nodes
declare these tables on themselves (`nodes.kit.node_parameters`).
"""
