"""Keyboard teleop of a driven car (docs/teleop.md): :mod:`.teleop`."""
