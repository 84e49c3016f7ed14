"""ODrive motor controllers over the CAN Simple protocol."""
