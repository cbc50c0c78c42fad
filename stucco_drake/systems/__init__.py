"""Drake LeafSystems: thin wrappers that own ports and events and call into ``core``."""
