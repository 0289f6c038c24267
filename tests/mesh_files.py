"""Meshes written to files for the tests that read them back."""


def write(mesh, folder, name):
    """Write ``mesh`` to folder/name (STL or OBJ by the suffix; OBJ with all digits)."""
    path = folder / name
    if name.endswith(".obj"):
        mesh.export(path, digits=17)
    else:
        mesh.export(path)
    return str(path)
