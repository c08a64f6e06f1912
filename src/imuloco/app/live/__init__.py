"""Live mode: a phone on the leg streams its sensors, a browser shows the walker as it walks.

:mod:`imuloco.app.live.session` turns raw samples into calibrated model-rate frames and poses (no
I/O, numpy only); :mod:`imuloco.app.live.server` (needs the ``[live]`` extra, ``websockets``) serves
the phone page, the live viewer and the websockets between them, and replays recorded logs.
"""

from imuloco.app.live.session import Frame, KernelResampler, LiveSession, kernel_resample

__all__ = ["Frame", "KernelResampler", "LiveSession", "kernel_resample"]
