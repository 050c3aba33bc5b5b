"""``gait-estimator``: the argparse front ends of every command. Imports ``ros`` only inside the
commands that need it, so the offline commands run without ROS installed."""

from .app import main

__all__ = ["main"]
