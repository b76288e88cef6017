"""Simulated world: a fake robot and camera that let the recorder run without hardware."""
