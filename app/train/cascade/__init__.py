"""A Viola-Jones cascade trainer (Haar features, Gentle AdaBoost stumps, bootstrapped negatives) that
writes OpenCV 4's cascade XML. Self-contained: needs numpy, OpenCV and tqdm, nothing else of Headway."""
from .haar import FeatureSet
from .model import Cascade, Stage
from .trainer import TrainParams, train

__all__ = ["Cascade", "FeatureSet", "Stage", "TrainParams", "train"]
