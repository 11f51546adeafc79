"""Reading and writing surfel clouds and triangle meshes (PLY, OBJ+MTL, OFF)."""
