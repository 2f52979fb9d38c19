"""Trajectory (and, later, analytics) scheduler plug-ins, installed as ``aerodaas.schedulers``."""
from .base import DEFAULT_PRIORITY, Mission, TrajectoryScheduler
from .nearest_neighbor import NearestNeighborScheduler

__all__ = ["TrajectoryScheduler", "NearestNeighborScheduler", "Mission", "DEFAULT_PRIORITY"]
