"""The names and ranges the library accepts from its user, in one module that imports nothing:
the command line shows them in ``--help`` and checks options against them without loading
numpy or scipy (issue #43), and the library checks its inputs against the same constants.

- :data:`FORMATS`: the sensor-log formats, in sniffing order (the names of
  :data:`imuloco.io.logformats.LOG_FORMATS`' rows, which that table checks as it is built);
- :data:`RIG_NAMES`: the rig presets of :data:`imuloco.core.rigs.PRESETS` (checked there
  likewise) and :data:`MODEL_RIG`, the model's own skeleton;
- a wearer's body height (:func:`imuloco.measures.gait.height_scale`), a log's median
  sampling rate (:func:`imuloco.sensors.reallog.read_log`) and the live mode's calibration
  time (:class:`imuloco.app.live.session.LiveSession`).
"""

FORMATS: tuple[str, ...] = ("generic", "realworld", "phyphox", "sensorlogger", "xsens")
RIG_PRESETS: tuple[str, ...] = ("bvh-default", "mixamo", "unreal", "unity")
MODEL_RIG = "model"  # the model's skeleton as it is, no preset
RIG_NAMES: tuple[str, ...] = (*RIG_PRESETS, MODEL_RIG)
MIN_HEIGHT_M, MAX_HEIGHT_M = 0.5, 2.6  # metres, a body height
MIN_RATE, MAX_RATE = 5.0, 10_000.0  # Hz, median source rate: gait needs > 5 Hz; IMUs < 10 kHz
MIN_CALIBRATE_S, MAX_CALIBRATE_S = 0.0, 60.0  # seconds; the longest bounds the live buffer
