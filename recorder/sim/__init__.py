"""Simulated world: scenarios, arena geometry, movement planner, renderer, and the fake robot and camera that let the recorder run without hardware."""
