"""Graph tests use ssa_fusion.graph.Graph (real processes, private domain, loopback)."""

from ssa_fusion.graph import Graph as RosGraph
from ssa_fusion.graph import Proc as NodeProcess

__all__ = ["NodeProcess", "RosGraph"]
