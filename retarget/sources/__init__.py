"""Performance sources: recorded takes, their files, trackers, filters and conditioning."""
