"""Calibration from recordings: replaying a recorded run and fitting the plant to it."""
