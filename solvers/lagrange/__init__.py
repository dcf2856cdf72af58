"""immerse package."""
