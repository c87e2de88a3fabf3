"""The output folder, written once: the final candidate's files published
from the refine's workspace (:mod:`asset2sim.tasks.assemble.candidate`)."""

from __future__ import annotations

from pathlib import Path

from asset2sim import atomic, file_names, mesh_io
from asset2sim.output_paths import OutputError
from asset2sim.tasks.assemble import write
from asset2sim.tasks.assemble.candidate import Candidate, Workspace


def publish(candidate: Candidate, workspace: Workspace, out_dir: Path) -> write.OutputPaths:
    """Write the output folder ``out_dir`` once, from the final ``candidate``:
    the collision pieces its overrides name that the refine made (copied from
    the workspace, where the repairs wrote them), then the SPEC's files and
    the meshes (:meth:`~asset2sim.tasks.assemble.candidate.Candidate.write_into`, containers opened as the
    workspace's engines loaded them). Every file is written atomically.

    Raises:
        OutputError: ``out_dir`` inside the input, an incomplete overlay, or a
            piece name leaving the folder.
    """
    taken = {g.filename for ln in candidate.asset.links for g in ln.collisions if g.filename}
    for rel in sorted({p.filename for pcs in candidate.collision_overrides.values() for p in pcs} - taken):
        try:
            src, dst = file_names.join_inside(workspace.root, rel), file_names.join_inside(out_dir, rel)
        except file_names.UnsafePath as exc:
            raise OutputError(f"collision piece {rel!r} would be written outside the output folder {out_dir}",
                              "OUTPUT_PATH_ESCAPES", Path(out_dir)) from exc
        atomic.write_bytes(dst, mesh_io.file_bytes(src))
    paths = candidate.write_into(out_dir, copy=True, open_containers=workspace.open_containers)  # as the engines loaded it
    mesh_io.forget_under(out_dir)  # nothing of this refine reads the output folder
    return paths
