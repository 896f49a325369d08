"""MQTT: track state out, commands in, availability by last will."""
