"""The built-in scenes: procedural interiors generated from room specifications."""
