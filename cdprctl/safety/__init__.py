"""What cdprctl does for the cell's safety beside the loop: the holding brakes' test and its
record (docs/safety.md)."""
