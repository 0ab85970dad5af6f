"""The registration workspace's model: everything the workspace shows, without Qt.

:class:`RegistrationSession` holds the rig, the recording (or a Plant3DImageReg plant), the
registrar and its result, the displayable layers and their renderings, the display settings per
modality, the masks source and the cursor. Every mutation goes through a method that emits an
:class:`~.events.Event`; the Qt views subscribe to those events and hold no state of their own (napari's
``ViewerModel``). The long steps are plain functions (``*_job``) that a worker thread runs and
whose result the session applies on the GUI thread; tests drive the session without Qt.

Events (``session.events.<name>``; callbacks get the arguments listed):

* ``source()``      rig / recording / plant changed (labels, target list, banner)
* ``raw()``         raw layers and their renderings replaced
* ``result()``      a registration result arrived, or was forgotten (``session.result`` None)
* ``display(name)`` one layer's display settings and renderings changed
* ``cursor()``      the cursor moved or what is read at it changed (``readout``, ``spectrum``)
* ``masks_source()`` the source camera whose cases the masks view and the read-out use
* ``busy()``        a job started or ended (``session.busy``)
* ``region()``      the region (``session.region``) or its statistics (``region_stats``) changed

Length: the workspace's one model (sources, result, layers, display settings, cursor, region)
and the worker functions that feed it; its event list above is the index.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from ..core.camera import modality
from ..core.registration.cases import Case, area_label, case_label
from ..core.geometry.depth import to_millimetres
from ..core.errors import InputError
from ..core.data.recording import MANIFEST, Recording
from ..core.camera.rig import Rig
from .events import Event, Events  # noqa: F401 (Event: what the views subscribe to)
from .layers import (
    DEPTH, Cloud, DisplaySettings, Layer, build_cloud, colour_bar_of, pca_basis, raw_layers, registered_layers,
    render,
)


# ---------------------------------------------------------------------- paths
#: first bytes of image files someone may pick as a rig by mistake -> what they are
_IMAGE_MAGIC = ((b"\x89PNG", "a PNG image"), (b"\xff\xd8\xff", "a JPEG image"), (b"II*\x00", "a TIFF image"),
                (b"MM\x00*", "a TIFF image"), (b"\x93NUMPY", "a NumPy array (.npy)"))
#: "format" of the project's other JSON files -> what they are and where they belong
_OTHER_FORMATS = {"plantreg.landmarks": "a landmarks file (open it in the Landmarks tab)",
                  "plantreg.calibration-report": "a calibration report"}
_RIG_IS = "a rig file is a .json listing the cameras with their intrinsics and extrinsics"


def check_is_rig_file(path: Path) -> None:
    """Refuse a file that is plainly something else (an image, an empty file, a recording
    manifest, a calibration session, any other JSON) with one line saying what it is, rather than
    a parser's complaint ("Expecting value", "invalid start byte", "the rig has no cameras")."""
    import json

    if not path.is_file():
        return  # Rig.load names the missing file
    try:
        with open(path, "rb") as f:
            head = f.read(1 << 20)
    except OSError:
        return  # Rig.load explains unreadable files
    for magic, what in _IMAGE_MAGIC:
        if head.startswith(magic):
            raise InputError(f"not a rig file ({what}); {_RIG_IS}", path)
    if not head.strip():
        raise InputError(f"not a rig file (the file is empty); {_RIG_IS}", path)
    try:
        d = json.loads(head.decode("utf-8"))
    except UnicodeDecodeError:
        raise InputError(f"not a rig file (binary data, not JSON text); {_RIG_IS}", path) from None
    except ValueError as e:
        if len(head) == 1 << 20:
            return  # a long file: Rig.load reads and explains it whole
        raise InputError(f"not a rig file (not valid JSON: {getattr(e, 'msg', e)} at line "
                         f"{getattr(e, 'lineno', '?')}); {_RIG_IS}", path) from None
    if not isinstance(d, dict):
        return  # Rig.load says the top level must be an object
    if d.get("format") in _OTHER_FORMATS:
        raise InputError(f"not a rig file ({_OTHER_FORMATS[d['format']]}); {_RIG_IS}", path)
    if "board" in d and isinstance(d.get("cameras"), dict):
        raise InputError("not a rig file (a calibration session: open its folder in the Calibration tab, "
                         "whose last page saves the rig)", path)
    if "cameras" not in d and d.get("format") != "plantreg.rig":
        what = "a recording manifest" if path.name == MANIFEST else "a JSON file without \"cameras\""
        raise InputError(f"not a rig file ({what}); a rig file lists the cameras with their intrinsics and "
                         "extrinsics", path)


def kind_of_path(p: Path) -> str:
    """What a dropped or given path is: ``"rig"`` (a JSON file), ``"manifest"`` (a recording.json),
    ``"dataset"`` (the Plant3DImageReg data set), ``"recording"`` (a recording folder) or
    ``"demo"`` (a folder with rig.json and recording/); :class:`InputError` for anything else."""
    from ..core.data import plant3d

    if p.is_file() and p.suffix.lower() == ".json":
        return "manifest" if p.name == MANIFEST else "rig"
    if p.is_dir() and plant3d.is_dataset(p):
        return "dataset"
    if p.is_dir() and (p / MANIFEST).is_file():
        return "recording"
    if p.is_dir() and (p / "rig.json").is_file() and (p / "recording" / MANIFEST).is_file():
        return "demo"
    if p.is_dir() and (p / "session.json").is_file():
        raise InputError("a calibration session, not a recording: open it in the Calibration tab, whose last "
                         "page saves the rig", p)
    raise InputError("not a rig file, a recording folder or the Plant3DImageReg data set", p)


# ---------------------------------------------------------------------- events
class SessionEvents(Events):
    NAMES = ("source", "raw", "result", "display", "cursor", "masks_source", "busy", "region")


# ---------------------------------------------------------------------- jobs (run on workers)
def render_layers(layers: list[Layer], settings: dict[str, DisplaySettings], progress,
                  pca: dict[str, Any] | None = None) -> dict[str, np.ndarray]:
    out = {}
    for i, L in enumerate(layers):
        progress(i / max(len(layers), 1), f"rendering {L.name}")
        out[L.name] = render(L.data, L.modality, settings.get(L.name), (pca or {}).get(L.name))
    return out


def raw_pca(rec: Recording, rig: Rig | None, settings: dict[str, DisplaySettings]) -> dict[str, Any]:
    """PCA false-colour bases of the recording's raw cubes: the registered cubes are drawn with
    them, so the same spectrum has the same colour in the raw and the registered view."""
    out = {}
    for name, img in rec.images.items():
        mod = rig.camera(name).modality if rig is not None and name in rig.names else name
        b = pca_basis(img, mod, settings.get(name))
        if b is not None:
            out[name] = b
    return out


def rig_beside(rec_path: Path) -> Path | None:
    """The ``rig.json`` that goes with a recording folder: in it, or in the folder above (the
    demo's layout), or None."""
    for cand in (rec_path / "rig.json", rec_path.parent / "rig.json"):
        if cand.is_file():
            return cand
    return None


def recording_for_plant(rig_path: Path | None, plant: str) -> Path | None:
    """The recording folder of a Plant3DImageReg ``plant`` that ships with a rig:
    ``<rig folder>/recordings/<plant>`` (resources/plant3dimagereg's layout), or None. Opening the
    data set's own plant folder shows the raw images only; this recording is what registers."""
    if rig_path is None:
        return None
    rec = Path(rig_path).parent / "recordings" / plant
    return rec if (rec / MANIFEST).is_file() else None


def fit_problem(rig: Rig, rec: Recording) -> str | None:
    """Why ``rec`` does not fit ``rig`` (Recording.check's message with its file), or None."""
    try:
        rec.check(rig)
    except InputError as e:
        return str(e)
    return None


def load_job(rig_path: Path | None, rec_path: Path, rig: Rig | None, settings, progress) -> dict:
    """Read a recording (and its rig when given by path) and render its raw images.

    With the open ``rig`` (``rig_path`` None) a recording that does not fit it is still read:
    with the ``rig.json`` beside it when that fits (the pair is opened together), else without a
    rig and ``"misfit"`` saying why, for the window to offer closing the open rig."""
    if rig is None and rig_path is not None:
        rig = Rig.load(rig_path)
    progress(0.05, "reading the recording")
    out: dict[str, Any] = {}
    if rig is not None and rig_path is None:  # the open rig: read first, then see whether it fits
        rec = Recording.load(rec_path)
        why = fit_problem(rig, rec)
        if why is not None:
            own = rig_beside(Path(rec_path))
            own_rig = Rig.load(own) if own is not None else None
            if own_rig is not None and fit_problem(own_rig, rec) is None:
                rig, rig_path = own_rig, own
                out["replaced_rig"] = why
            else:
                out["misfit"] = why
                rig = None
    else:
        rec = Recording.load(rec_path, rig)
        if rig is not None:
            rec.check(rig)
    layers = raw_layers(rig, rec)
    renders = render_layers(layers, settings, progress.sub(0.6, 1.0))
    out.update({"rig": rig, "rig_path": rig_path, "recording": rec, "recording_path": rec_path,
                "layers": layers, "renders": renders})
    return out


#: Write the demo in a child process: building the scene holds the GIL for seconds in Open3D
#: calls (mesh conversion, BVH), which froze the GUI thread from a worker thread.
DEMO_IN_PROCESS = True


def demo_job(folder: Path, settings, progress) -> dict:
    from ..core import synthetic
    from ..core.jobs.process_job import call_in_process

    progress(0.0, "writing the demo rig and recording")
    # the calibration session is the wizard's business; leaving it out halves the start-up
    if DEMO_IN_PROCESS:
        call_in_process(synthetic.write_demo, folder, calibration=False, progress=progress.sub(0.0, 0.6))
    else:
        synthetic.write_demo(folder, calibration=False, progress=progress.sub(0.0, 0.6))
    out = load_job(folder / "rig.json", folder / "recording", None, settings, progress.sub(0.6, 1.0))
    out["demo"] = True
    return out


def register_job(registrar, rig: Rig, rec: Recording, target: str, settings, progress, params=None) -> dict:
    """Register (reusing ``registrar``'s meshes), render the layers and build the point cloud.
    ``params`` (RegistrationParams) for a new registrar (the pipeline's :func:`register`, as the
    command line's)."""
    from ..core.pipeline.pipeline import register

    registrar, result = register(rig, rec, target, params, progress.sub(0.0, 0.85), registrar=registrar)
    layers = registered_layers(result, rig)
    pca = raw_pca(rec, rig, settings)
    renders = render_layers(layers, settings, progress.sub(0.85, 0.97), pca)
    progress(0.97, "building the point cloud")
    cloud = build_cloud(result.points_rig, layers, renders)
    meshes = {}
    m = getattr(registrar, "meshes", None)
    if m is not None:  # core.register.Meshes: TriMesh object and uncertainty meshes
        for label, mesh in (("object mesh", m.object), ("uncertainty mesh", m.uncertainty)):
            if mesh is not None and len(mesh.triangles):
                meshes[label] = (np.asarray(mesh.vertices, np.float32), np.asarray(mesh.triangles, np.int64))
    # everything the GUI thread would otherwise compute on arrival
    box = object_box(result.points_rig)
    progress(1.0, "done")
    return {"registrar": registrar, "result": result, "layers": layers, "renders": renders, "pca": pca,
            "cloud": cloud, "meshes": meshes, "box": box, "summary": summary_html(result),
            "worst": worst_source(result.cases)}


def plant3d_job(folder: Path, plant: str, settings, progress) -> dict:
    from ..core.data import plant3d

    p = plant3d.load_plant(folder, plant, progress.sub(0.0, 0.5))
    layers = []
    for name, img in p.images.items():
        data = to_millimetres(img, 0.001) if name == "depth" else img  # the data set's depth is in mm
        layers.append(Layer(name, p.modalities[name], data, None, p.units[name]))
    renders = render_layers(layers, settings, progress.sub(0.5, 0.9))
    cloud = Cloud(p.points, p.point_pixels)
    for L in layers:
        if L.data.shape[:2] == p.depth_shape:
            cloud.colours[L.name] = renders[L.name].reshape(-1, 3)[p.point_pixels]
            cloud.values[L.name] = L.data.reshape(-1)[p.point_pixels].astype(np.float32)
            cloud.modalities[L.name] = L.modality
    return {"plant": p, "layers": layers, "renders": renders, "cloud": cloud}


def mask_of(shape: tuple[int, int], region: tuple[str, Any]) -> np.ndarray:
    """(H, W) bool of a session region (("rect", (x0, y0, x1, y1)) or ("polygon", [(x, y), ...]))."""
    from ..core.registration.region import region_mask

    kind, geom = region
    return region_mask(shape, **({"rect": geom} if kind == "rect" else {"polygon": geom}))


def region_job(result: Any, region: tuple[str, Any], sources: list[str],
               info: dict[str, tuple[Any, str]], progress=None) -> list:
    """core.region statistics of ``sources`` over ``region`` of ``result``; ``info[source]`` =
    (wavelengths or None, unit). Returns the RegionStats in ``sources`` order."""
    from ..core.progress import ensure_reporter
    from ..core.registration.region import region_stats

    rep = ensure_reporter(progress)
    mask = mask_of(result.shape, region)
    out = []
    for i, src in enumerate(sources):  # each source reports (and can be cancelled) chunk by chunk
        wl, unit = info.get(src, (None, ""))
        n = max(len(sources), 1)
        out.append(region_stats(result, mask, src, wl, unit, progress=rep.sub(i / n, (i + 1) / n)))
    return out


REGION_FORMAT = "plantreg.region"


def region_to_json(region: tuple[str, Any], target: str, shape: tuple[int, int]) -> str:
    """A region as a versioned JSON text: kind, geometry in target pixels, and the target camera
    and its (H, W) size it was drawn on (checked when it is loaded)."""
    import json

    kind, geom = region
    g = [float(v) for v in geom] if kind == "rect" else [[float(x), float(y)] for x, y in geom]
    return json.dumps({"format": REGION_FORMAT, "version": 1, "kind": kind, "shape": g, "target": target,
                       "target_size": [int(shape[1]), int(shape[0])]}, indent=1) + "\n"


def region_from_json(text: str, target: str, shape: tuple[int, int], path: Path | None = None) -> tuple[str, Any]:
    """The region of :func:`region_to_json`'s text for a result on ``target`` of (H, W) ``shape``;
    :class:`InputError` (naming ``path``) for another file, another target or size, or a bad shape."""
    import json

    try:
        d = json.loads(text)
    except ValueError as e:
        raise InputError(f"not a region file (not valid JSON: {getattr(e, 'msg', e)})", path) from None
    if not isinstance(d, dict) or d.get("format") != REGION_FORMAT:
        raise InputError(f"not a region file (\"format\" is not \"{REGION_FORMAT}\")", path)
    if d.get("version") != 1:
        raise InputError(f"region file version {d.get('version')!r} is not one this plantreg reads (1)", path)
    w, h = int(shape[1]), int(shape[0])
    if d.get("target") != target or list(d.get("target_size") or []) != [w, h]:
        raise InputError(f"the region was drawn on {d.get('target')} ({'x'.join(map(str, d.get('target_size') or []))}), "
                         f"the result is on {target} ({w}x{h}): register into that camera first", path)
    kind, g = d.get("kind"), d.get("shape")
    try:
        if kind == "rect":
            geom: Any = tuple(float(v) for v in g)
            ok = len(geom) == 4
        elif kind == "polygon":
            geom = [(float(x), float(y)) for x, y in g]
            ok = len(geom) >= 3
        else:
            ok = False
    except (TypeError, ValueError):
        ok = False
    if not ok or not all(np.isfinite(np.asarray(geom, float)).ravel()):
        raise InputError("the region's \"kind\" must be rect (4 numbers) or polygon (3 or more [x, y])", path)
    return kind, geom


def region_csv(result: Any, region: tuple[str, Any], sources: list[str], info: dict[str, tuple[Any, str]],
               progress=None) -> str:
    from ..core.registration.region import stats_csv

    kind, geom = region
    desc = (f"rect x {min(geom[0], geom[2]):.1f}-{max(geom[0], geom[2]):.1f} "
            f"y {min(geom[1], geom[3]):.1f}-{max(geom[1], geom[3]):.1f}" if kind == "rect"
            else f"polygon {len(geom)} corners")
    return stats_csv(region_job(result, region, sources, info, progress), desc)


def summary_html(r: Any) -> str:
    """The side panel's summary of a result: size, slowest stages, case counts per source."""
    h, w = r.shape
    lines = [f"<b>Target {r.target}</b> ({w}x{h})"]
    if r.timings:
        stages = {k: v for k, v in r.timings.items() if k != "total"}
        total = r.timings.get("total", sum(stages.values()))
        top = sorted(stages.items(), key=lambda kv: -kv[1])[:4]
        lines.append(f"registration {total:.2f} s (slowest: " + ", ".join(f"{k} {v:.2f} s" for k, v in top) + ")")
    n = h * w
    for cam, codes in r.cases.items():
        cc = np.bincount(np.asarray(codes, np.uint8).ravel(), minlength=8)
        p1, obj = int(cc[Case.P1]), n - int(cc[Case.BACKGROUND])
        lines.append(f"{cam}: P1 {p1:,} ({100 * p1 / max(obj, 1):.1f}% of object), P2 {int(cc[Case.P2]):,}, "
                     f"P3.1 {int(cc[Case.P31]):,}, P3.2 {int(cc[Case.P32]):,}")
    return "<br>".join(lines)


def worst_source(cases: dict[str, np.ndarray]) -> str | None:
    """The source with the most occluded or uncertain pixels: the one worth checking first."""
    if not cases:
        return None
    bad = {n: int(np.bincount(np.asarray(c, np.uint8).ravel(), minlength=8)[[Case.P2, Case.P31, Case.P32]].sum())
           for n, c in cases.items()}
    return max(bad, key=bad.get)


def object_box(points_rig: np.ndarray, margin: float = 0.08
               ) -> tuple[tuple[float, float, float, float] | None, tuple[int, int] | None]:
    """Box (x0, y0, x1, y1) in pixels, with a margin, of the target pixels with an object hit, and
    the object pixel nearest the box centre as (row, col); (None, None) if nothing was hit."""
    ok = np.isfinite(points_rig[..., 2])
    rows_any = np.flatnonzero(ok.any(axis=1))
    if rows_any.size == 0:
        return None, None
    cols_any = np.flatnonzero(ok.any(axis=0))
    h, w = ok.shape
    r0, r1, c0, c1 = rows_any[0], rows_any[-1] + 1, cols_any[0], cols_any[-1] + 1
    m = margin * max(r1 - r0, c1 - c0)
    rect = (float(max(c0 - m, 0)), float(max(r0 - m, 0)), float(min(c1 + m, w)), float(min(r1 + m, h)))
    rows, cols = np.nonzero(ok[r0:r1, c0:c1])
    rc, cc = (r1 - r0) / 2, (c1 - c0) / 2
    i = int(np.argmin((rows - rc) ** 2 + (cols - cc) ** 2))
    return rect, (int(rows[i] + r0), int(cols[i] + c0))


# ---------------------------------------------------------------------- the model
@dataclass
class RegistrationSession:
    """See the module docstring. Read the fields; change them only through the methods."""

    rig: Rig | None = None
    rig_path: Path | None = None
    recording: Recording | None = None
    recording_path: Path | None = None
    plant: Any = None                        # core.plant3d.Plant3DRecording
    is_demo: bool = False                    # the open recording is the temporary demo
    registrar: Any = None
    result: Any = None                       # core.register.RegistrationResult
    raw: list[Layer] = field(default_factory=list)
    raw_renders: dict[str, np.ndarray] = field(default_factory=dict)
    layers: list[Layer] = field(default_factory=list)        # registered (target grid)
    renders: dict[str, np.ndarray] = field(default_factory=dict)
    cloud: Cloud | None = None
    meshes: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    home: tuple[float, float, float, float] | None = None    # object box in the target grid
    display: dict[str, DisplaySettings] = field(default_factory=dict)
    pca: dict[str, Any] = field(default_factory=dict)         # raw cubes' false-colour bases
    params: Any = None                                        # core.register.RegistrationParams
    masks_source: str | None = None
    summary: str = ""                                          # HTML, see summary_html()
    cursor: tuple[str, int, int] | None = None                # (layer or "target", row, col)
    readout: str = ""
    spectrum: tuple[np.ndarray, np.ndarray | None, str, str] | None = None   # values, nm, title, unit
    busy: dict[int, tuple[str, str]] = field(default_factory=dict)   # job id -> (kind, title)
    pending_target: str | None = None
    region: tuple[str, Any] | None = None    # ("rect", (x0, y0, x1, y1)) or ("polygon", [(x, y), ...]), target px
    region_stats: Any = None                  # core.region.RegionStats of the masks source over the region
    region_token: int = 0                     # which region/source the statistics being computed belong to
    region_grid: tuple[str, tuple[int, int]] | None = None   # (target, (H, W)) the region was drawn on
    region_note: str = ""                     # why the last region was cleared ('' = it was not)
    stats_runner: Callable[[tuple, int], None] | None = field(default=None, repr=False)  # see _region_changed
    generation: int = 0
    events: SessionEvents = field(default_factory=SessionEvents, repr=False)

    def __post_init__(self) -> None:
        if self.params is None:
            from ..core.registration.params import RegistrationParams

            self.params = RegistrationParams()

    def set_params(self, params: Any) -> None:
        """New registration parameters for the next Register (the meshes are rebuilt with them)."""
        if params != self.params:
            self.params = params
            self.registrar = None

    # ------------------------------------------------------------------ queries
    def default_export_folder(self) -> Path:
        """Beside the recording; for the demo, in the home folder: the demo lives in a temporary
        folder that is deleted when the window closes, and an export in it would go with it."""
        target = self.result.target if self.result is not None else "target"
        if self.recording_path is None:
            return Path.home()
        if self.is_demo:
            return Path.home() / f"plantreg-demo-registered-{target}"
        # named for the recording: recordings side by side (a data set's plants) would otherwise
        # share one default folder, and each export replace the last plant's
        return self.recording_path.parent / f"{self.recording_path.name}-registered-{target}"

    def settings_for(self, name: str) -> DisplaySettings:
        return self.display.get(name, DisplaySettings())

    def can_register(self) -> bool:
        return self.rig is not None and self.recording is not None and self.rig.depth_camera is not None

    def busy_with(self, kind: str) -> bool:
        return any(k == kind for k, _ in self.busy.values())

    def is_busy(self) -> bool:
        return bool(self.busy) or self.pending_target is not None

    def layer(self, name: str, registered: bool = True) -> Layer | None:
        return next((L for L in (self.layers if registered else self.raw) if L.name == name), None)

    def colour_layer(self) -> str | None:
        """The layer that colours the point cloud by default: the colour camera, else the target."""
        name = next((L.name for L in self.layers if modality.is_colour(L.modality)), None)
        return name or (self.result.target if self.result is not None else None)

    def has_cube(self) -> bool:
        return any(L.is_cube for L in self.raw + self.layers)

    # ------------------------------------------------------------------ jobs
    def job_started(self, job_id: int, kind: str, title: str) -> None:
        self.busy[job_id] = (kind, title)
        self.events.busy.emit()

    def job_ended(self, job_id: int) -> None:
        self.busy.pop(job_id, None)
        self.events.busy.emit()

    # ------------------------------------------------------------------ opening
    def set_rig(self, rig: Rig, path: Path | None) -> None:
        """Use ``rig`` (checked against the open recording first: raises before anything changes)."""
        if self.recording is not None:
            self.recording.check(rig)
        self.rig, self.rig_path = rig, path
        self.plant = None
        self.forget_registration()
        self.forget_cursor()
        if self.recording is not None:
            self.raw = raw_layers(rig, self.recording)
            self.raw_renders = {L.name: render(L.data, L.modality, self.settings_for(L.name)) for L in self.raw}
            self.events.raw.emit()
        self.events.source.emit()

    def close(self) -> None:
        """File ▸ Close: forget the rig, the recording or plant and the result (display settings stay)."""
        self.rig = self.rig_path = self.recording = self.recording_path = self.plant = None
        self.is_demo = False
        self.pending_target = None
        self.forget_registration()
        self.raw, self.raw_renders = [], {}
        self.forget_cursor()
        self.events.raw.emit()
        self.events.source.emit()

    def apply_loaded(self, out: dict) -> None:
        """A :func:`load_job` / :func:`demo_job` result (``"misfit"``: shown without the open rig)."""
        self.plant = None
        if out.get("misfit"):
            self.rig = self.rig_path = None
        elif out["rig"] is not None and out["rig"] is not self.rig:
            self.rig, self.rig_path = out["rig"], out["rig_path"]
        self.recording, self.recording_path = out["recording"], out["recording_path"]
        self.is_demo = bool(out.get("demo"))
        self.forget_registration()
        self.raw, self.raw_renders = out["layers"], out["renders"]
        self.forget_cursor()  # the read-out was of the data just replaced
        self.events.raw.emit()
        self.events.source.emit()

    def apply_plant(self, out: dict) -> None:
        """A :func:`plant3d_job` result: the plant replaces rig and recording (no calibration)."""
        self.rig = self.rig_path = self.recording = self.recording_path = None
        self.is_demo = False
        self.forget_registration()
        self.plant = out["plant"]
        self.raw, self.raw_renders = out["layers"], out["renders"]
        self.cloud = out["cloud"]
        self.pending_target = None
        self.forget_cursor()
        self.events.raw.emit()
        self.events.result.emit()  # the 3D view shows the plant's own cloud
        self.events.source.emit()

    def forget_cursor(self) -> None:
        """No cursor, read-out or spectrum: what they said belongs to data no longer open."""
        had = self.cursor is not None or self.readout or self.spectrum is not None
        self.cursor, self.readout, self.spectrum = None, "", None
        if had:
            self.events.cursor.emit()

    def forget_registration(self) -> None:
        self.generation += 1  # results of registrations still running belong to the old data
        had = self.result is not None or self.cloud is not None
        self.registrar = self.result = self.cloud = self.home = None
        self.summary = ""
        self.layers, self.renders, self.meshes = [], {}, {}
        if had:
            self.events.result.emit()
        self.set_region(None)

    def apply_registered(self, out: dict, generation: int | None = None) -> bool:
        """A :func:`register_job` result; ignored (False) when other data was opened meanwhile."""
        if generation is not None and generation != self.generation:
            return False
        self.registrar, self.result = out["registrar"], out["result"]
        self.layers, self.renders, self.cloud = out["layers"], out["renders"], out["cloud"]
        self.meshes = out.get("meshes", {})
        self.pca = dict(out.get("pca", {}))
        self.home, centre = out.get("box") or object_box(self.result.points_rig)
        self.summary = out["summary"] if "summary" in out else summary_html(self.result)
        if self.masks_source not in self.result.cases:
            self.masks_source = out["worst"] if "worst" in out else worst_source(self.result.cases)
        self.events.result.emit()
        self.events.masks_source.emit()
        if self.region is not None:
            grid = (self.result.target, tuple(self.result.shape))
            if self.region_grid not in (None, grid):  # another camera's pixels: another place
                was = self.region_grid
                self.set_region(None)
                self.region_note = (f"The region drawn on {was[0]} ({was[1][1]}x{was[1][0]}) was cleared: "
                                    f"{grid[0]} is another pixel grid. Draw it again or load a region.")
                self.events.region.emit()
            else:  # a new result (other parameters): the same region's new statistics
                self._region_changed()
        if centre is not None:  # start with the cursor on the object so every read-out has a value
            self.hover("target", *centre)
        return True

    # ------------------------------------------------------------------ display
    def set_display(self, name: str, settings: DisplaySettings) -> None:
        """New settings for one layer: re-render it wherever it is shown, then emit ``display``."""
        self.display[name] = settings
        raw = self.layer(name, registered=False)
        if raw is not None and name in self.pca:  # refit for the new limits, shared by raw and registered
            self.pca[name] = pca_basis(raw.data, raw.modality, settings)
        for L in self.raw:
            if L.name == name:
                self.raw_renders[name] = render(L.data, L.modality, settings)
                if self.plant is not None and self.cloud is not None and name in self.cloud.colours:
                    self.cloud.colours[name] = self.raw_renders[name].reshape(-1, 3)[self.cloud.pixels]
        for L in self.layers:
            if L.name == name:
                self.renders[name] = render(L.data, L.modality, settings, self.pca.get(name))
                if self.cloud is not None and name in self.cloud.colours:
                    self.cloud.colours[name] = self.renders[name].reshape(-1, 3)[self.cloud.pixels]
        self.events.display.emit(name)

    def release_unlocked_limits(self) -> None:
        """Before another recording is opened: absolute limits that are not locked belong to the
        recording they were set on; the next one is drawn by its percentiles again."""
        for name, st in list(self.display.items()):
            if st.limits is not None and not st.locked:
                self.display[name] = st.with_(limits=None)

    def set_masks_source(self, name: str) -> None:
        if name == self.masks_source:
            return
        self.masks_source = name
        self.events.masks_source.emit()
        if self.region is not None:  # the region's statistics are the masks source's
            self._region_changed()
        if self.cursor is not None:  # the read-out names the case of this source: refresh it now
            self.hover(*self.cursor)

    # ------------------------------------------------------------------ region tool
    def set_region(self, kind: str | None, shape: Any = None) -> None:
        """Select a region of the target image: ``("rect", (x0, y0, x1, y1))`` or ``("polygon",
        [(x, y), ...])`` in target pixel coordinates (pixel (r, c) covers [c, c+1) x [r, r+1));
        ``None`` clears it. Computes the masks source's statistics over it (core/registration/region.py)."""
        new = None if kind is None else (kind, shape)
        if new is None and self.region is None:
            return
        self.region = new
        self.region_note = ""
        r = self.result
        self.region_grid = None if new is None or r is None else (r.target, tuple(r.shape))
        self._region_changed()

    def _camera_info(self, name: str) -> tuple[Any, str]:
        L = self.layer(name)
        return (None, "") if L is None else (L.wavelengths, L.unit)

    def _region_changed(self) -> None:
        """Start the statistics of the masks source over the region: through ``stats_runner`` (the
        workspace runs it on a worker: a 4K cube takes seconds) or at once (tests, scripts)."""
        self.region_token += 1
        self.region_stats = None
        r = self.result
        src = None if r is None else (self.masks_source if self.masks_source in r.registered else r.target)
        if self.region is not None and src is not None:
            job = (region_job, r, self.region, [src], {src: self._camera_info(src)})
            if self.stats_runner is not None:
                self.stats_runner(job, self.region_token)
            else:
                self.apply_region_stats(job[0](*job[1:])[0], self.region_token)
                return
        self.events.region.emit()

    def apply_region_stats(self, stats: Any, token: int) -> None:
        """A :func:`region_job` result (its first entry); ignored when the region or source changed since."""
        if token == self.region_token:
            self.region_stats = stats
            self.events.region.emit()

    def region_csv_job(self) -> tuple:
        """(function, *args) that returns every camera's statistics over the region as CSV text
        (run it on a worker); raises :class:`InputError` without a region."""
        if self.region is None or self.result is None:
            raise InputError("draw a region on the registered images first")
        names = [L.name for L in self.layers if L.name in self.result.registered]
        return (region_csv, self.result, self.region, names, {n: self._camera_info(n) for n in names})

    def region_csv(self) -> str:
        """Every camera's statistics over the region (target first), as core.region.stats_csv's CSV."""
        job = self.region_csv_job()
        return job[0](*job[1:])

    # ------------------------------------------------------------------ cursor and read-out
    def band_for(self, L: Layer) -> int | None:
        s = self.settings_for(L.name)
        return s.bands[0] if s.bands is not None else L.middle_band

    @staticmethod
    def _case_flag(r: Any, name: str, row: int, col: int) -> str:
        """The case label of source ``name`` at a target pixel when it is not P1 (legitimate) or
        background; '' otherwise, or for a camera that is not a source of ``r``."""
        cases = None if r is None else r.cases.get(name)
        if cases is None or not (0 <= row < cases.shape[0] and 0 <= col < cases.shape[1]):
            return ""
        code = int(cases[row, col])
        return "" if code in (int(Case.P1), int(Case.BACKGROUND)) else case_label(code)

    def hover(self, where: str, row: int, col: int) -> None:
        """The cursor is at (row, col) of ``where``: 'target' (the registered grid) or a raw layer's name.
        Leaving an image (row < 0) keeps the last cursor and read-out (the pixel under study)."""
        if row < 0:
            return
        if where == "target":
            if not self.layers:
                return
            parts = [f"x={col} y={row}"]
            r = self.result
            for L in self.layers:
                text = f"{L.name}: {L.value_text(row, col, self.band_for(L))}"
                # a source's value that is not legitimate here says so beside it (an occluded
                # thermal pixel carries the occluder's temperature; the one case shown after the
                # values is the masks' source's only)
                flag = self._case_flag(r, L.name, row, col)
                parts.append(f"{text} [{flag}]" if flag and not text.endswith("—") else text)
            if r is not None and self.masks_source in r.cases:
                h, w = r.shape
                if 0 <= row < h and 0 <= col < w:
                    parts.append(f"{self.masks_source} case: {case_label(r.cases[self.masks_source][row, col])}")
                    parts.append(f"area: {area_label(r.area[row, col])}")
            self.readout = "   ".join(parts)
            spec = next(((L, s) for L in self.layers if (s := L.spectrum(row, col)) is not None), None)
            title = "" if spec is None else f"{spec[0].name} at x={col}, y={row}"
        else:
            L = self.layer(where, registered=False)
            if L is None:
                return
            self.readout = (f"{where} (raw {L.data.shape[1]}x{L.data.shape[0]})  x={col} y={row}: "
                            f"{L.value_text(row, col, self.band_for(L))}")
            s = L.spectrum(row, col)
            spec = None if s is None else (L, s)
            title = f"{where} (raw) at x={col}, y={row}"
        if spec is not None:
            L, s = spec
            self.spectrum = (s, L.wavelengths, title, L.unit)  # all NaN = not mapped: the plot says so
        self.cursor = (where, row, col)
        self.events.cursor.emit()

    # ------------------------------------------------------------------ what the views say when empty
    def empty_note(self, needs: str) -> str:
        """Why a view that ``needs`` 'raw', 'result' or 'cloud' is empty and what fills it ('' = not empty)."""
        loading = [t for k, t in self.busy.values() if k == "load"]
        registering = self.busy_with("register") or (self.pending_target is not None and bool(self.busy))
        if loading and not self.raw:
            raw = f"{loading[0]}… the images appear here when read."
        elif self.raw:
            raw = ""
        elif self.rig is not None:
            raw = ("Rig open. Now open the recording that goes with it (Open recording…, or drop its "
                   "folder here): its raw images are shown in Raw images at once.")
        else:
            raw = "Open a rig and a recording (File menu, or drop a folder here), or File ▸ Load demo."
        if needs == "raw":
            return raw
        if needs == "cloud" and self.cloud is not None:
            return ""
        if self.result is not None:
            return ""
        if registering:
            return f"Registering into {self.pending_target or self.busy_title('register')}… this view fills in " \
                   "when it is done."
        if self.plant is not None:
            return ("Nothing registered: no calibration ships with this data set, and registration needs a rig "
                    "file with the cameras' intrinsics and extrinsics.\nThe raw images are in Raw images, "
                    "the depth camera's point cloud in 3D.")
        if self.rig is not None and self.recording is not None:
            return "Not registered yet: choose the target camera in the toolbar and press Register."
        return raw or "Open a rig and a recording, then press Register."

    def busy_title(self, kind: str) -> str:
        t = next((t for k, t in self.busy.values() if k == kind), "")
        return t.removeprefix("Registering into ")

    def summary_html(self) -> str:
        return self.summary

    def mask_layers(self) -> list[tuple[str, np.ndarray, str]]:
        """Extra boolean masks of the result in the target grid, when it has them: (name, (H, W)
        bool, what it means) - the masks source's mixed edge pixels, and the flying pixels the
        depth filter removed (when the target is the depth camera, whose grid they are in)."""
        r = self.result
        if r is None:
            return []
        out = []
        mixed = (getattr(r, "mixed", None) or {}).get(self.masks_source)
        if mixed is not None and mixed.shape == r.shape:
            out.append(("mixed edge pixels", np.asarray(mixed, bool),
                        f"P1 pixels whose footprint in {self.masks_source} reaches across a silhouette"))
        flying = getattr(r, "flying", None)
        if flying is not None and flying.shape == r.shape:
            repaired = self.params is None or getattr(self.params, "flying_repair", True)
            out.append(("flying pixels", np.asarray(flying, bool),
                        "depth pixels between two surfaces, " + (
                            "moved onto the surface they mostly saw" if repaired else "removed") + " before meshing"))
        return out

    def colour_bar(self, L: Layer) -> tuple[str | None, tuple[float, float] | None, str]:
        """(colour map, (lo, hi) limits in the layer's unit, unit) of a single-band layer as drawn;
        (None, None, '') for colour and multi-band images (no colour bar)."""
        return colour_bar_of(L, self.settings_for(L.name))

    def layer_title(self, L: Layer, raw: bool = False) -> str:
        h, w = L.data.shape[:2]
        what = "z of the hit point" if (L.name == DEPTH and not raw) else L.modality
        # a camera named after its modality does not say it twice ("hyperspectral (hyperspectral,
        # 100 bands, 640x576)" was cut off at the edge of a side-by-side view)
        parts = [p for p in (None if what == L.name else what, L.unit or None,
                             f"{L.bands} bands" if L.is_cube else None, f"{w}x{h}") if p]
        return f"{L.name}  ({', '.join(parts)})"

    def export_display_options(self) -> dict[str, dict[str, Any]]:
        """Per camera, the keyword arguments of ``display.to_rgb8`` that reproduce the screen."""
        opts = {}
        for L in self.layers:
            if L.name == DEPTH:
                continue
            s = self.settings_for(L.name)
            o: dict[str, Any] = {"percentiles": tuple(s.percentiles)}
            if s.cmap:
                o["cmap"] = s.cmap
            if s.limits is not None:
                o["limits"] = tuple(s.limits)
            if s.bands is not None and L.is_cube:
                o["bands"] = tuple(s.bands)
            elif L.name in self.pca:
                o["pca"] = self.pca[L.name]  # the export's false colour is the screen's
            opts[L.name] = o
        return opts

    def check_target(self, target: str | None) -> str:
        if self.rig is None or self.recording is None:
            raise InputError("open a rig and a recording first")
        if target not in self.rig.names:
            raise InputError(f"unknown target camera '{target}'; the rig has {', '.join(self.rig.names)}")
        return target


__all__ = ["Event", "RegistrationSession", "fit_problem", "recording_for_plant", "rig_beside", "load_job", "demo_job", "register_job", "plant3d_job", "object_box"]
