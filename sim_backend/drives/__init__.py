"""Drive emulators: CAN nodes that answer the frames real drives answer."""
