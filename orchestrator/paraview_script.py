"""OUT/open_in_paraview.py: a ParaView Python script that opens a run's results.xdmf as its users expect:
one block per solver group named by its role (ale, lagrange, sph), the background's pressure
coloured over the range of every output step (zones a body fills whole are NaN in the output, drawn
in grey under the body: they do not pull the range to 0), the bodies over it, and the time controls
on the outputs.  Run it with ``paraview --script=OUT/open_in_paraview.py`` (the GUI) or
``IMMERSE_PARAVIEW_PNG=last.png pvbatch OUT/open_in_paraview.py`` (a picture of the last output step).

Why a script and not only the XDMF file: ParaView's default XDMF reader (Xdmf3ReaderS) reads the
groups' collections as unnamed pieces "0" and "1"; the legacy XDMF reader keeps their names, and
ExtractBlock by name then gives each group its own colouring.  Written by the coupler when a run
starts (the file names nothing of this machine: it finds results.xdmf beside itself).
"""
from __future__ import annotations

from pathlib import Path

NAME = "open_in_paraview.py"

_SCRIPT = '''"""Open this run's results in ParaView (written by immerse; orchestrator/paraview_script.py).

    paraview --script=open_in_paraview.py                       the GUI, each group coloured
    IMMERSE_PARAVIEW_PNG=last.png pvbatch open_in_paraview.py   a picture of the last output step
"""
import os

from paraview import simple

HERE = os.path.dirname(os.path.abspath(__file__))
ROLES = {roles!r}
BACKGROUND = {background!r}
FIELD = {field!r}


def open_results():
    """(reader, {{role: its block}}, output times): the legacy XDMF reader keeps one block per group
    named by its role (the default reader numbers them)."""
    results = simple.XDMFReader(registrationName="results", FileNames=[os.path.join(HERE, "results.xdmf")])
    results.UpdatePipelineInformation()
    times = list(results.TimestepValues) if results.TimestepValues else [0.0]
    blocks = {{role: simple.ExtractBlock(registrationName=role, Input=results, Selectors=["/Root/" + role])
              for role in ROLES}}
    return results, blocks, times


def field_range(block, times, field=FIELD):
    """The field's (lo, hi) over every output step (NaN where bodies fill a zone: not in it)."""
    lo = hi = None
    for t in times:
        block.UpdatePipeline(t)
        if field not in block.CellData.keys():
            continue
        a, b = block.CellData[field].GetRange()
        if a <= b:
            lo, hi = (a, b) if lo is None else (min(lo, a), max(hi, b))
    return lo, hi


def show(blocks, times):
    view = simple.GetActiveViewOrCreate("RenderView")
    view.ViewTime = times[-1]
    for role, block in blocks.items():
        shown = simple.Show(block, view)
        if role == BACKGROUND:
            simple.ColorBy(shown, ("CELLS", FIELD))
            lut = simple.GetColorTransferFunction(FIELD)
            lut.NanColor = [0.75, 0.75, 0.75]
            lo, hi = field_range(block, times)
            if lo is not None:
                lut.RescaleTransferFunction(lo, hi if hi > lo else lo + 1.0)
                lut.AutomaticRescaleRangeMode = "Never"
            shown.SetScalarBarVisibility(view, True)
        else:
            simple.ColorBy(shown, None)
            shown.DiffuseColor = [0.85, 0.85, 0.85]
            shown.SetRepresentationType("Surface With Edges")
    view.ResetCamera()
    simple.Render(view)
    return view


if __name__ == "__main__":
    _, found, when = open_results()
    shown_view = show(found, when)
    png = os.environ.get("IMMERSE_PARAVIEW_PNG")
    if png:
        simple.SaveScreenshot(png, shown_view, ImageResolution=[1024, 768])
'''


def script(roles: list[str], background: str | None, field: str = "pressure") -> str:
    """The script's text for a run of these roles (``background``: the coupled background's role)."""
    return _SCRIPT.format(roles=list(roles), background=background, field=field)


def write(out: Path, roles: list[str], background: str | None) -> Path:
    """OUT/open_in_paraview.py, written beside and renamed over."""
    path = Path(out) / NAME
    tmp = path.with_name(NAME + ".tmp")
    tmp.write_text(script(roles, background))
    tmp.replace(path)
    return path
