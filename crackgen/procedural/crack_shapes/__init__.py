"""Crack shape families other than the thesis fBm map: fracture, network, hairline.

Each family draws centre-line paths (``paths.Path``: texel coordinates plus a half-width per
vertex) from its own Generator; ``paths.render_paths`` turns them into the normalised
distance field that ``crackgen.procedural.crackmap`` makes the mask and depth from.
"""
