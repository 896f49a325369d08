"""The simulated PTZ dome: a wide video warped by a rotation-only camera model."""
