"""Hydra configs of gyrodenoise (a package, so that the installed console scripts find them as pkg://gyrodenoise.conf)."""
