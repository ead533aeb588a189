"""rclpy nodes of ssa_fusion, one per module, each with `main()` for `ros2 run`."""

from ssa_fusion import limit_blas_threads

limit_blas_threads()
