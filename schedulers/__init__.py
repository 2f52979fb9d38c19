"""Trajectory (and, later, analytics) scheduler plug-ins, installed as ``aerodaas.schedulers``."""
from aerodaas.schedulers.base import DEFAULT_PRIORITY, Mission, TrajectoryScheduler
from aerodaas.schedulers.nearest_neighbor import NearestNeighborScheduler
from aerodaas.schedulers.two_opt import TwoOptScheduler

__all__ = ["TrajectoryScheduler", "NearestNeighborScheduler", "TwoOptScheduler", "Mission", "DEFAULT_PRIORITY"]
