"""ptzd: a real-time PTZ camera auto-tracking daemon."""

__version__ = "0.1.0"
