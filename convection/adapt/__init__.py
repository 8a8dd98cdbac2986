"""Mesh changes during a run: error indicators and adaptivity, the mesh hierarchy every mesh is
refined from, the transfer of fields between meshes, and repartitioning across ranks."""

from convection.adapt.adaptivity import Adaptivity, AdaptivitySettings
from convection.adapt.hierarchy import MeshHierarchy
from convection.adapt.rebalance import Balancer, RankLoads
from convection.adapt.transfer import PointEvaluator, transfer_function

__all__ = ["Adaptivity", "AdaptivitySettings", "Balancer", "MeshHierarchy", "PointEvaluator", "RankLoads",
           "transfer_function"]
