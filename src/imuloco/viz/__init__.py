"""Looking at motions: stick-figure videos (GIF, MP4), an offline HTML viewer and plots.

Needs the ``viz`` extra (matplotlib, imageio, imageio-ffmpeg); every module imports matplotlib
with the non-interactive Agg backend, so rendering works without a display.
"""
