"""The simulated world: scenarios, arena geometry, movement planner, renderer, fake devices."""
