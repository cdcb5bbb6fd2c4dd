"""Motion exporters to interchange formats (glTF binary, ...)."""
