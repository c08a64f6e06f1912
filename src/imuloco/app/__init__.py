"""The application layer: what the command line runs, as library functions.

:mod:`imuloco.app.pipeline` takes one phone recording to an animation and a report,
:mod:`imuloco.app.batch` many recordings at once, :mod:`imuloco.app.live` a phone streaming to
a browser. Everything below (``io`` to ``viz``) is a library these three compose.
"""
