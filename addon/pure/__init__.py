"""The add-on's modules that need no ``bpy``: NumPy and the tracer only, so they run (and are tested) outside
Blender.  Blender's data goes in and out through the modules one level up.

* ``convert``: SDL <-> Blender numbers (axes, float32 snapshots, shear);
* ``raycam``: rays for Blender's camera, exactly as Blender projects;
* ``primitives``: the polygon meshes that stand for the generic shapes;
* ``blocks``: tracing a film in blocks, coarse to fine, with threads, cancelling and time slices;
* ``passes``: the render passes besides Combined (depth, normal, albedo, position, mist);
* ``naming``: the names Blender gives datablocks made in bulk, and the order to make them in.
"""
