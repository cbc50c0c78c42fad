"""Blind Object Retrieval on our iiwa scenes: the BOR Diagram (``diagram``), one episode
(``episode``), its logs for the tables (``log``), the grasp after rummaging (``grasp``) and the
``run`` and ``diagram`` commands (``cli``)."""
