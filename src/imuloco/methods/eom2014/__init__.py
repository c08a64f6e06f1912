"""Eom, Choi, Noh 2014 ("Data-driven reconstruction of human locomotion using a single
smartphone"): :mod:`.gplvm` (GPLVM with velocity GP), :mod:`.hmm` (phase segmentation),
:mod:`.mlp` (sensor -> latent regressions), :mod:`.method` (the registered ``eom2014``)."""

from imuloco.methods.eom2014.method import Eom2014

__all__ = ["Eom2014"]
