"""ocp package."""
