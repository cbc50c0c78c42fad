"""stucco_drake: soft tracking of contacts in clutter (STUCCO) on Drake."""
