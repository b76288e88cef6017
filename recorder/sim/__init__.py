"""Simulated world: scenarios, arena geometry, movement planner, renderer, fake robot and camera.

They let the recorder run without hardware.
"""
