"""The ``antialias`` modes of :class:`renderers.Renderer`, importable without numpy, OpenCV or GL
(``paz6d generate``'s flags list them)."""

#: ``antialias`` values: 4× multisampled colour pass, single-sample with softened outlines, none.
ANTIALIAS_MODES = ("msaa", "edges", "none")
