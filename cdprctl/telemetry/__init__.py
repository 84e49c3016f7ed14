"""Zenoh telemetry, status and commands: a gateway process beside the loop's process."""
