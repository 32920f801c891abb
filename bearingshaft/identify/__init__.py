"""Identification: the model's uncertain parameters fitted to a measured hammer test (issue 26)."""
