"""The daemon: real-time loop, OS real-time settings, systemd notification, `cdprctl run`."""
