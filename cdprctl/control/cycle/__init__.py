"""One control cycle's stages, their bundles and their compiled kernels, composed by the
Controller."""
