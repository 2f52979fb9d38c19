"""The training run's images: every set read and checked (:func:`load_training_data`), the validation images (given,
or split off by video/sequence), and each training image's draw weight. No PyTorch here: labels are checked before
the training stack is even imported."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aerodaas.training.config import TrainConfig
from aerodaas.training.dataset import labelled_classes, load_set, split_by_sequence
from aerodaas.training.labels.check import LabelError
from aerodaas.training.labels.images import LabelledImage

__all__ = ["TrainingData", "load_training_data"]


@dataclass
class TrainingData:
    """The checked training and validation images, the class names, and each training image's draw weight."""

    train: list[LabelledImage]
    val: list[LabelledImage]
    names: list[str]
    weights: np.ndarray


def load_training_data(cfg: TrainConfig) -> TrainingData:
    """Read and check every set of ``cfg`` (all problems of all sets in one :class:`LabelError`)."""
    problems, sets, names = [], [], cfg.names
    for d in cfg.data:
        try:
            items, n = load_set(d, names)
            labelled = labelled_classes(d, n)
            for it in items:
                it.labelled = labelled
        except LabelError as e:
            problems += e.problems
            continue
        if names is None:
            names = n
        elif n != names:
            problems.append(f"{d}: class names {n} differ from {names} (pass --names to map every set alike)")
        sets.append(items)
    val = []
    for v in cfg.val:
        try:
            val += load_set(v, names)[0]
        except LabelError as e:
            problems += e.problems
    if problems:
        raise LabelError("training data", problems)
    w = np.concatenate([np.full(len(s), 1.0 / len(s) if cfg.balance_sources else 1.0) for s in sets])
    train = [it for s in sets for it in s]
    if not cfg.val:
        tr, val = split_by_sequence(train, cfg.val_fraction, cfg.seed)
        train_set = {id(t) for t in tr}
        w = np.array([wi for wi, it in zip(w, train) if id(it) in train_set])
        train = tr
    if not any(len(it.boxes) for it in train):
        raise LabelError("training data", ["no box in the training images: nothing to learn"])
    return TrainingData(train, val, list(names), w)
