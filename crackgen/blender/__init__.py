"""The only place bpy is imported. Imported by the generator worker alone."""
