"""Pan/tilt/zoom control: pure, clock-injected controllers."""
