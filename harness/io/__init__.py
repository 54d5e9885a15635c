"""Reading meshes: files through meshio (and the original B&C program's format), named groups."""
