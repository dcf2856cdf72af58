"""Embedded-mesh coupling: interface geometry, operators B, the multiplier solve and its variants."""
