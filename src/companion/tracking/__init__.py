"""Tracking the person: detections in, the person's state with its uncertainty out."""

from companion.tracking.imm import coordinated_turn, process_noise
from companion.tracking.tracker import PersonTracker, Reidentify
from companion.tracking.walker import Belief, WalkerFilter, exact_detection, is_exact, predict

__all__ = ["Belief", "PersonTracker", "Reidentify", "WalkerFilter", "coordinated_turn",
           "exact_detection",
           "is_exact", "predict", "process_noise"]
