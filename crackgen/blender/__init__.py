"""The only place bpy is imported. Imported by the generator worker alone.

Importing bpy appends Blender's script folders to ``sys.path``; one of them holds a
pure-Python ``bpy`` package that shadows the real extension module. A process started
with ``spawn`` inherits that ``sys.path`` from a parent that already imported bpy, and
its ``import bpy`` then fails with "No module named '_bpy'". Dropping those folders
before the first import here makes workers independent of what the parent imported.
"""
import os as _os
import sys as _sys

if "bpy" not in _sys.modules:
    _marker = _os.sep + _os.path.join("bpy", "")  # ".../site-packages/bpy/<ver>/scripts/..."
    _sys.path[:] = [p for p in _sys.path if not (_marker in p and _os.sep + "scripts" in p)]
