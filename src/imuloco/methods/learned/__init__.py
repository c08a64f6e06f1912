"""imuloco's own learned reconstructor (needs the ``[deep]`` extra: torch).

- :mod:`.model`: the causal network and torch forward kinematics;
- :mod:`.train`: augmentation and the training loop;
- :mod:`.method`: the ``learned`` method (offline, streaming, the other leg, saving);
- :mod:`.export`: ONNX export.
"""

from imuloco.methods.learned.method import Learned, LearnedStream, Prediction

__all__ = ["Learned", "LearnedStream", "Prediction"]
