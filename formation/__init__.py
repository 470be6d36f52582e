"""formation package."""
