"""Track 2: run a submission's ``train.py`` in the sandbox (:func:`train`) and store what it
wrote as one archive with its sha256 (:mod:`evaluator.training.model`)."""

from evaluator.training.model import MODEL_ARCHIVE, folder_digest, pack_model, unpack_model
from evaluator.training.run import TrainFailure, TrainingResult, TrainingStopped, train

__all__ = [
    "MODEL_ARCHIVE",
    "TrainFailure",
    "TrainingResult",
    "TrainingStopped",
    "folder_digest",
    "pack_model",
    "train",
    "unpack_model",
]
