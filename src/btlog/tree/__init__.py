"""Trees: the structure model, the registry of node types and the XML loader."""
