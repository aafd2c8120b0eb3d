"""voxwarp: deform polygon models by warping the space they live in.

A mesh is voxelized into a density volume (a voxmap), warped by a cubic B-spline lattice steered by point
constraints, and re-polygonized. This package is the Python face of voxwarp's C++ libraries.

Arrays: V is a float64 (n, 3) array of world positions, F an int32 (m, 3) array of 0-based triangle indices,
counter-clockwise seen from outside. Arrays returned by voxwarp own their memory (no copy is made on the way out).

    V, F = voxwarp.read_mesh("bunny.obj")
    V2, F2, report = voxwarp.deform(V, F, "bunny_ear.json", resolution=128)
    voxwarp.write_mesh("ear.ply", V2, F2)

Functions
    read_mesh(path, attributes=False) -> (V, F), or (V, F, attributes)
    write_mesh(path, V, F, attributes=None)  written to a temporary file and renamed: never half written
    voxelize(V, F, resolution=128 | voxel_size=h, padding=3, sign="auto", max_memory=None, progress=None) -> Voxmap
    extract(voxmap, isovalue=0.5, adaptivity=0.0, mesher="mc", progress=None) -> (V, F)
    deform(V, F, edit, resolution=128 | voxel_size=h, mode="volume", preview=False, max_steps=8, faces=0,
           mesher="mc", sign="auto", max_memory=None, progress=None) -> (V, F, report)
        mesher: "mc" (marching cubes, smooth) or "features" (sharp edges and corners put back, about 1.1-1.4x the time; faces can touch, to round-off, where a model has sharp edges), as --mesher;
        sign: "auto", "flood-fill" or "winding-number", as --sign (the report's "sign" and "sign_note" say which ran);
        edit: a dict in the edit-file schema (README.md, "Edit files") or a path to an edit file;
        report: the dict `voxwarp deform --report` writes (residuals, surface misses, volumes, timings).
    deform(..., attributes=A) -> (V, F, report, attributes): the input's attributes in, the output's out.

Attributes (texture coordinates, normals, colours, materials, groups; README.md, "Texture coordinates, normals,
colours, materials and groups"), a dict with the keys the mesh has: "uv" float64 (k, 2) and "uv_index" int32 (m, 3)
(each triangle's corners' rows of uv, -1: none), "normal" float64 (k, 3) and "normal_index" int32 (m, 3) likewise
(per-corner normals, carried through a deform as normals turn), "colour" float32 (n, 3) in [0, 1], "material" int32 (m,) (index into "materials",
-1: none), "materials": [{"name", "diffuse", "texture", "statements"}], "group" int32 (m,) (index into "groups", -1:
none), "groups": [names] (OBJ's g and o). A missing .mtl or texture is a UserWarning.

Voxmap
    Voxmap(density, origin=(0, 0, 0), voxel_size=1.0): from a (nx, ny, nz) array (copied).
    .density: float32 (nx, ny, nz) view, density[i, j, k] is voxel (i, j, k), whose centre is
              origin + voxel_size * (i, j, k); 1 = material, the surface is the 0.5 isosurface.
    .origin, .voxel_size, .dims, .enclosed_volume()

set_threads(n): most worker threads voxwarp uses (0 = all cores); outputs do not depend on it.

Long calls release the GIL. `progress(stage, fraction)` is called at most every 0.1 s; returning False cancels
(raises Cancelled). Ctrl-C cancels too (raises KeyboardInterrupt).

Errors: Error (a RuntimeError) and its kinds InvalidInput (also a ValueError), ResourceLimit (also a MemoryError),
SolverFailure, IOError (also an OSError) and Cancelled, with the command line's messages.

Batch runs on Dask: voxwarp.batch.deform_many(jobs), or python3 -m voxwarp.batch JOBS.json.
"""

from ._voxwarp import (  # noqa: F401
    Cancelled,
    Error,
    InvalidInput,
    IOError,
    ResourceLimit,
    SolverFailure,
    Voxmap,
    deform,
    extract,
    read_edit,
    read_mesh,
    set_threads,
    voxelize,
    write_mesh,
)

__all__ = [
    "Cancelled", "Error", "InvalidInput", "IOError", "ResourceLimit", "SolverFailure", "Voxmap",
    "deform", "extract", "read_edit", "read_mesh", "set_threads", "voxelize", "write_mesh",
]
