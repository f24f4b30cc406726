"""Partitioned simplification of meshes larger than one process: read in chunks and bin into spatially
compact parts (`scatter`), simplify the parts in parallel with their borders locked, regroup neighbouring
parts so that the former borders lie inside a group, unlock them and simplify again, until one group meets the
target (`run`)."""
