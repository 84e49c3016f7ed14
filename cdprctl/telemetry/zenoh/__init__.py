"""The Zenoh gateway process and the daemon's link to it: payloads, command validation, security."""
