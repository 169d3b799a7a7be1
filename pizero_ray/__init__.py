"""PiZero with a Ray trainer."""
