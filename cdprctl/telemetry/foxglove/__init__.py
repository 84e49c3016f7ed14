"""The live Foxglove view process and the scene it draws."""
