"""Virtual and real body-worn sensors: placements, simulation, noise, log import, calibration."""
