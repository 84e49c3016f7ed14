"""The control layer: one cycle (cycle/), its commands (intake/), its supervision (supervision/),
its loop (lifecycle/); at the top what the rest reads of it."""
