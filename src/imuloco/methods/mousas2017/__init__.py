"""Mousas 2017: full-body locomotion from one IMU with a hierarchical multivariate HMM and
reactive interpolation (Sensors 17, 2589).

Pipeline, one module per step: :mod:`.registration` (gait-phase segments, DTW registration),
:mod:`.features` (x_t and y_t), :mod:`.model` (frame-state Gaussians and regression),
:mod:`.forward` (transitions and the scaled forward algorithm), :mod:`.stream` (online
reconstruction) and :mod:`.compiled` (its step as numba kernels, the ``fast`` extra),
:mod:`.method` (the registered estimator ``mousas2017``).
"""

from imuloco.methods.mousas2017.method import Mousas2017

__all__ = ["Mousas2017"]
