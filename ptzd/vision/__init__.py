"""Vision: detection and particle-filter tracking."""
