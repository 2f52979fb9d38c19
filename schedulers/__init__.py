"""Trajectory (and, later, analytics) scheduler plug-ins, installed as ``aerodaas.schedulers``."""
from .base import DEFAULT_PRIORITY, Mission, TrajectoryScheduler
from .nearest_neighbor import NearestNeighborScheduler
from .two_opt import TwoOptScheduler

__all__ = ["TrajectoryScheduler", "NearestNeighborScheduler", "TwoOptScheduler", "Mission", "DEFAULT_PRIORITY"]
