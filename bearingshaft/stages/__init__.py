"""One module per pipeline stage: each reads a scene and writes its files."""
