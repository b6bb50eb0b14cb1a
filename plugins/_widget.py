"""The osmobulge dock widgets: thin magicgui shells over :class:`~osmobulge.plugins._session.CurationSession`.

- :class:`CurationWidget`: browse frames, exclude/include a frame with a reason,
  set the time origin and the chamber regions, and watch V/V0(t) (a small
  matplotlib plot) follow every decision.
- :class:`ProfilePicker`: click points on the membrane of the current frame;
  they snap to the membrane (sub-pixel), an ellipse and a spline are fitted and
  drawn live; accept stores the manual profile; CSV / ImageJ ROI import and
  export; semi-automatic tracing between picked frames.

Keyboard shortcuts (viewer-wide, bound by either widget): ``n`` / ``Shift-Right``
next frame, ``b`` / ``Shift-Left`` previous frame, ``Enter`` accept the picks,
``Shift-X`` exclude the frame (reason from the curation widget, else "other"),
``Shift-U`` include it again.

Every computation and every file write happens in the session and the
libraries it calls; the callbacks here only read controls and draw layers.
"""

from __future__ import annotations

import contextlib
import weakref

import numpy as np
from magicgui.widgets import (
    CheckBox,
    ComboBox,
    Container,
    FileEdit,
    FloatSpinBox,
    Label,
    LineEdit,
    PushButton,
)

from osmobulge.experiments.curation import REASONS
from osmobulge.plugins._logic import layer_data_to_picks, rectangles_to_regions, regions_to_rectangles
from osmobulge.plugins._reader import AUTO_LAYER, AXIS_LABELS, UNITS, auto_profile_layer_data, find_session

__all__ = ["CurationWidget", "ProfilePicker", "bind_shortcuts", "open_experiment", "SHORTCUTS"]

PICKS_LAYER = "picked points"
FIT_LAYER = "profile fit"
REGIONS_LAYER = "chamber regions"
#: key -> action name, bound on the viewer
SHORTCUTS = {
    "n": "next_frame",
    "Shift-Right": "next_frame",
    "b": "previous_frame",
    "Shift-Left": "previous_frame",
    "Enter": "accept",
    "Shift-X": "exclude",
    "Shift-U": "include",
}
#: colours of the live fits: spline (pending / accepted) and ellipse
COLORS = {"pending": "orange", "accepted": "lime", "ellipse": "cyan", "points": "red"}

# widgets of each viewer, so the shortcuts reach whichever is open
_WIDGETS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _layer_kwargs(session) -> dict:
    p_um = session.pixel_size * 1e6
    return {"scale": (1.0, p_um, p_um), "axis_labels": AXIS_LABELS, "units": UNITS}


def _current_frame(viewer, session) -> int:
    step = viewer.dims.current_step[0] if viewer.dims.ndim >= 3 else 0
    return int(np.clip(step, 0, session.n_frames - 1))


def _set_frame(viewer, session, frame: int) -> None:
    frame = int(np.clip(frame, 0, session.n_frames - 1))
    viewer.dims.set_current_step(0, frame)


def _get_layer(viewer, name):
    return viewer.layers[name] if name in viewer.layers else None  # noqa: SIM401 (LayerList has no .get)


# --------------------------------------------------------------------------- shortcuts
def bind_shortcuts(viewer) -> None:
    """Bind the osmobulge keyboard shortcuts (:data:`SHORTCUTS`) on a viewer."""

    def action(name):
        def run(v):
            widgets = _WIDGETS.get(v, {})
            session = find_session(v)
            if session is None:
                return
            frame = _current_frame(v, session)
            if name == "next_frame":
                _set_frame(v, session, frame + 1)
            elif name == "previous_frame":
                _set_frame(v, session, frame - 1)
            elif name == "accept" and "picker" in widgets:
                widgets["picker"].accept()
            elif name == "exclude":
                cw = widgets.get("curation")
                if cw is not None:
                    cw.exclude()
                else:
                    session.exclude(frame, "other", "keyboard shortcut")
            elif name == "include":
                session.include(frame)

        run.__name__ = f"osmobulge_{name}"
        return run

    for key, name in SHORTCUTS.items():
        viewer.bind_key(key, action(name), overwrite=True)


def _register(viewer, role, widget) -> None:
    with contextlib.suppress(TypeError):
        _WIDGETS.setdefault(viewer, {})[role] = widget
    bind_shortcuts(viewer)


# --------------------------------------------------------------------------- curation
class CurationWidget(Container):
    """Browse frames, exclude/include them, set the time origin and regions; V/V0(t) plot.

    Parameters
    ----------
    napari_viewer : napari.Viewer
        The viewer holding an experiment opened with the osmobulge reader.
    """

    def __init__(self, napari_viewer):
        super().__init__(labels=False)
        self.viewer = napari_viewer
        self.session = find_session(napari_viewer)
        self._status = Label(value="open an experiment folder (File > Open Folder...)")
        self._prev = PushButton(text="< previous (b)")
        self._next = PushButton(text="next (n) >")
        self._reason = ComboBox(choices=list(REASONS), value="other", label="reason")
        self._note = LineEdit(value="", label="note")
        self._exclude = PushButton(text="Exclude frame (Shift-X)")
        self._include = PushButton(text="Include frame (Shift-U)")
        self._keep = PushButton(text="Keep although flagged")
        self._t0 = FloatSpinBox(value=0.0, min=-1e6, max=1e6, step=1.0, label="t0 (min, frame clock)")
        self._t0_set = PushButton(text="Set time origin")
        self._t0_here = PushButton(text="Time origin = this frame")
        self._regions = PushButton(text="Chamber regions from rectangles")
        self._message = Label(value="")
        nav = Container(widgets=[self._prev, self._next], layout="horizontal", labels=False)
        exc = Container(widgets=[self._reason, self._note, self._exclude, self._include, self._keep], labels=True)
        t0 = Container(widgets=[self._t0, self._t0_set, self._t0_here], labels=True)
        self.extend([self._status, nav, exc, t0, self._regions, self._message])
        self._prev.changed.connect(lambda: self.step(-1))
        self._next.changed.connect(lambda: self.step(+1))
        self._exclude.changed.connect(self.exclude)
        self._include.changed.connect(self.include)
        self._keep.changed.connect(self.keep_flagged)
        self._t0_set.changed.connect(self.set_time_origin)
        self._t0_here.changed.connect(self.set_time_origin_here)
        self._regions.changed.connect(self.set_regions)
        self.figure, self.ax, self.canvas = self._make_plot()
        napari_viewer.dims.events.current_step.connect(self._on_step)
        napari_viewer.layers.events.inserted.connect(self._on_step)
        _register(napari_viewer, "curation", self)
        if self.session is not None:
            self.session.listeners.append(self._on_session)
            if self.session.curation.time_origin is not None:
                self._t0.value = self.session.curation.time_origin / 60.0
            self._show_regions()
        self.refresh()

    # ------------------------------------------------------------------ plot
    def _make_plot(self):
        from matplotlib.backends.backend_qtagg import FigureCanvasQTAgg
        from matplotlib.figure import Figure

        fig = Figure(figsize=(3.6, 2.4), dpi=90, layout="constrained")
        ax = fig.add_subplot()
        canvas = FigureCanvasQTAgg(fig)
        canvas.setMinimumHeight(180)
        self.native.layout().addWidget(canvas)
        return fig, ax, canvas

    def plot_data(self) -> dict:
        """What the V/V0(t) plot shows (arrays; for tests and scripts)."""
        ds = self.session.volume_series()
        t = ds["time"].values / 60.0
        vr = ds["volume_ratio"].values
        return {
            "time_min": t,
            "volume_ratio": vr,
            "kept": ds["kept"].values.astype(bool),
            "excluded": ds["excluded"].values.astype(bool),
            "manual": ds["profile_source"].values.astype(str) == "manual",
        }

    def _redraw(self, frame):
        ax = self.ax
        ax.clear()
        d = self.plot_data()
        t, vr = d["time_min"], d["volume_ratio"]
        unused = ~d["kept"] & ~d["excluded"]
        ax.plot(t[d["kept"]], vr[d["kept"]], "o", ms=3, color="tab:blue", label="used")
        if unused.any():
            ax.plot(t[unused], vr[unused], "o", ms=3, mfc="none", color="tab:gray", label="flagged / before t0")
        if d["excluded"].any():
            ax.plot(t[d["excluded"]], vr[d["excluded"]], "x", ms=5, color="tab:red", label="excluded")
        if d["manual"].any():
            ax.plot(t[d["manual"]], vr[d["manual"]], "D", ms=5, mfc="none", color="tab:green", label="manual")
        ax.axvline(t[frame], color="k", lw=0.8, alpha=0.5)
        ax.axvline(0.0, color="tab:orange", lw=0.8, ls="--")
        ax.set_xlabel("t (min)")
        ax.set_ylabel("V/V0")
        ax.legend(fontsize=6, loc="upper left", frameon=False)
        self.canvas.draw_idle()

    # ------------------------------------------------------------------ state
    def _on_step(self, event=None):
        self.refresh()

    def _on_session(self, what, frame):
        if what == "extraction":
            layer = _get_layer(self.viewer, AUTO_LAYER)
            data, kwargs, _ = auto_profile_layer_data(self.session)
            if layer is None:
                if data:
                    self.viewer.add_shapes(data, **{k: v for k, v in kwargs.items() if k != "ndim"}, ndim=3)
            else:
                layer.data = data
                layer.edge_color = kwargs["edge_color"]
        self.refresh()

    @property
    def frame(self) -> int:
        return _current_frame(self.viewer, self.session) if self.session is not None else 0

    def refresh(self) -> None:
        """Update the status line and the plot for the current frame."""
        if self.session is None:
            self.session = find_session(self.viewer)
            if self.session is None:
                return
            self.session.listeners.append(self._on_session)
        s = self.session.frame_status(self.frame)
        parts = [f"frame {s['frame'] + 1}/{s['n_frames']}", f"t = {s['time_min']:.1f} min"]
        if s["flag"] is not None:
            parts.append(f"auto: {s['flag']}")
        if s["excluded"]:
            parts.append(f"EXCLUDED ({s['excluded']})")
        elif s["kept_flagged"]:
            parts.append("kept although flagged")
        if s["manual"]:
            parts.append("manual profile")
        if np.isfinite(s["volume_ratio"]):
            parts.append(f"V/V0 = {s['volume_ratio']:.3f}")
        self._status.value = " | ".join(parts)
        self._redraw(s["frame"])

    def _guard(self, func, *args):
        try:
            func(*args)
        except Exception as err:  # shown to the user, never swallowed silently
            self._message.value = f"not saved: {err}"
            raise
        else:
            self._message.value = "saved"

    # ------------------------------------------------------------------ actions
    def step(self, delta: int) -> None:
        """Go ``delta`` frames forward (negative: back)."""
        _set_frame(self.viewer, self.session, self.frame + int(delta))

    def exclude(self) -> None:
        """Exclude the current frame with the chosen reason and note."""
        self._guard(self.session.exclude, self.frame, self._reason.value, self._note.value)

    def include(self) -> None:
        """Include the current frame again."""
        self._guard(self.session.include, self.frame)

    def keep_flagged(self) -> None:
        """Keep the current frame in the fits although the automatic extraction flagged it."""
        self._guard(self.session.keep_flagged, self.frame, self._note.value)

    def set_time_origin(self) -> None:
        """Set t = 0 to the spin box value (minutes of the frame clock)."""
        self._guard(self.session.set_time_origin, float(self._t0.value) * 60.0)

    def set_time_origin_here(self) -> None:
        """Set t = 0 at the current frame."""
        self._t0.value = float(self.session.times[self.frame]) / 60.0
        self.set_time_origin()

    def _show_regions(self):
        rects = regions_to_rectangles(self.session.chamber_regions())
        layer = _get_layer(self.viewer, REGIONS_LAYER)
        if layer is None:
            kw = _layer_kwargs(self.session)
            layer = self.viewer.add_shapes(name=REGIONS_LAYER, ndim=2, edge_color="magenta", face_color="transparent",
                                           edge_width=2.0, scale=kw["scale"][1:], axis_labels=AXIS_LABELS[1:],
                                           units=UNITS[1:], visible=bool(rects))
        if rects:
            layer.data = rects
            layer.shape_type = ["rectangle"] * len(rects)
        return layer

    def set_regions(self) -> None:
        """Chamber regions from the rectangles of the "chamber regions" shapes layer."""
        layer = _get_layer(self.viewer, REGIONS_LAYER) or self._show_regions()
        if not len(layer.data):
            layer.visible = True
            self.viewer.layers.selection.active = layer
            layer.mode = "add_rectangle"
            self._message.value = "draw one rectangle per chamber, then press the button again"
            return
        regions = rectangles_to_regions(layer.data, shape=self.session.shape)
        self._guard(self.session.set_chamber_regions, regions)


# --------------------------------------------------------------------------- picking
class ProfilePicker(Container):
    """Pick membrane points on the current frame; live snap and fits; accept, import, export.

    Parameters
    ----------
    napari_viewer : napari.Viewer
        The viewer holding an experiment opened with the osmobulge reader.
    """

    def __init__(self, napari_viewer):
        super().__init__(labels=False)
        self.viewer = napari_viewer
        self.session = find_session(napari_viewer)
        self._snap = CheckBox(value=True, text="snap to membrane")
        self._search = FloatSpinBox(value=6.0, min=1.0, max=50.0, step=0.5, label="snap search (px)")
        self._info = Label(value="")
        self._accept = PushButton(text="Accept profile (Enter)")
        self._clear = PushButton(text="Clear points of this frame")
        self._remove = PushButton(text="Remove saved manual profile")
        self._semi = PushButton(text="Semi-automatic: trace between picked frames")
        self._keep_priors = PushButton(text="Keep picks as priors (used by every later extraction)")
        self._reprocess = PushButton(text="Re-run extraction with manual profiles")
        self._rim = PushButton(text="Rim = ends of this frame's picks (flat frame)")
        self._rim_clear = PushButton(text="Clear the rim")
        self._file = FileEdit(mode="w", filter="Points (*.csv *.zip *.roi)", label="points file")
        self._import = PushButton(text="Import points")
        self._export = PushButton(text="Export points")
        self._message = Label(value="")
        io = Container(widgets=[self._file, Container(widgets=[self._import, self._export], layout="horizontal",
                                                          labels=False)], labels=True)
        self.extend([Container(widgets=[self._snap, self._search], labels=True), self._info, self._accept,
                     self._clear, self._remove, self._semi, self._keep_priors, self._reprocess,
                     Container(widgets=[self._rim, self._rim_clear], layout="horizontal", labels=False), io,
                     self._message])
        self._updating = False
        self._building = False
        self._accept.changed.connect(self.accept)
        self._clear.changed.connect(self.clear)
        self._remove.changed.connect(self.remove)
        self._semi.changed.connect(self.semi_automatic)
        self._keep_priors.changed.connect(self.keep_priors)
        self._reprocess.changed.connect(self.reprocess)
        self._rim.changed.connect(self.set_rim)
        self._rim_clear.changed.connect(self.clear_rim)
        self._import.changed.connect(lambda: self.import_points(self._file.value))
        self._export.changed.connect(lambda: self.export_points(self._file.value))
        self.points_layer = None
        self.fit_layer = None
        if self.session is not None:
            self._make_layers()
            self.session.listeners.append(self._on_session)
        napari_viewer.dims.events.current_step.connect(self._on_step)
        napari_viewer.layers.events.inserted.connect(self._on_step)
        _register(napari_viewer, "picker", self)
        self.draw()

    # ------------------------------------------------------------------ layers
    def _make_layers(self):
        self._building = True  # adding layers fires `inserted`, which redraws
        try:
            self._add_layers()
        finally:
            self._building = False

    def _add_layers(self):
        from osmobulge.plugins._logic import picks_to_layer_data

        kw = _layer_kwargs(self.session)
        p_um = self.session.pixel_size * 1e6
        self.fit_layer = _get_layer(self.viewer, FIT_LAYER) or self.viewer.add_shapes(
            name=FIT_LAYER, ndim=3, edge_width=1.0, face_color="transparent", **kw)
        self.points_layer = _get_layer(self.viewer, PICKS_LAYER) or self.viewer.add_points(
            picks_to_layer_data(self.session.picks), name=PICKS_LAYER, ndim=3, size=2.5 * p_um,
            face_color=COLORS["points"], border_color="white", border_width=0.1, out_of_slice_display=False, **kw)
        self.points_layer.events.data.connect(self._on_points)
        self.viewer.layers.selection.active = self.points_layer
        self.points_layer.mode = "add"

    @property
    def frame(self) -> int:
        return _current_frame(self.viewer, self.session) if self.session is not None else 0

    def _frame_rows(self, data, frame):
        return np.rint(np.asarray(data)[:, 0]).astype(int) == frame if len(data) else np.zeros(0, bool)

    def _on_points(self, event=None):
        action = str(getattr(event, "action", "changed"))
        if self._updating or action not in ("added", "removed", "changed"):
            return
        frame = self.frame
        data = np.asarray(self.points_layer.data)
        picks = layer_data_to_picks(data).get(frame, np.empty((0, 2)))
        self.set_points(picks)

    def set_points(self, points_rc, frame: int | None = None) -> None:
        """Replace the current frame's points (snapped if the box is ticked) and redraw the fits."""
        frame = self.frame if frame is None else int(frame)
        self.session.set_picks(frame, points_rc, snap=bool(self._snap.value), search=float(self._search.value))
        self._sync_points(frame)
        self.draw()

    def _sync_points(self, frame):
        data = np.asarray(self.points_layer.data).reshape(-1, 3)
        keep = data[~self._frame_rows(data, frame)]
        mine = self.session.picks.get(frame, np.empty((0, 2)))
        new = np.vstack([keep, np.column_stack([np.full(len(mine), frame, float), mine])])
        self._updating = True
        try:
            self.points_layer.data = new
        finally:
            self._updating = False

    def _on_step(self, event=None):
        self.draw()

    def _on_session(self, what, frame):
        if what in ("extraction", "accepted"):
            self.draw()

    def draw(self) -> None:
        """Draw the current frame's live spline and ellipse and show its volume and area."""
        if self._building:
            return
        if self.session is None:
            self.session = find_session(self.viewer)
            if self.session is None:
                return
            self._make_layers()
            self.session.listeners.append(self._on_session)
        frame = self.frame
        fit = self.session.fit(frame)
        accepted = self.session.is_manual(frame) and np.array_equal(
            self.session.picks.get(frame, np.empty((0, 2))),
            self.session.manual_fit(frame).points_rc if self.session.manual_fit(frame) is not None else None)
        shapes, colors = [], []
        if len(fit.ellipse_rc) >= 2:
            shapes.append(np.column_stack([np.full(len(fit.ellipse_rc), frame, float), fit.ellipse_rc]))
            colors.append(COLORS["ellipse"])
        if len(fit.spline_rc) >= 2:  # drawn last: on top of the ellipse
            shapes.append(np.column_stack([np.full(len(fit.spline_rc), frame, float), fit.spline_rc]))
            colors.append(COLORS["accepted" if accepted else "pending"])
        self.fit_layer.data = []
        if shapes:
            self.fit_layer.add_paths(shapes, edge_color=colors, edge_width=1.0)
        if fit:
            vr = 1.0 + fit.volume / self.session.chamber_volume
            self._info.value = (f"{len(fit.points_rc)} points | V = {fit.volume * 1e12:.4g} nL | "
                                f"A = {fit.area * 1e6:.4g} mm2 | V/V0 = {vr:.3f}"
                                + (" | saved" if accepted else ""))
        else:
            n = len(self.session.picks.get(frame, ()))
            self._info.value = f"{n} points" + (f" ({fit.message})" if fit.message and n else "")

    # ------------------------------------------------------------------ actions
    def _guard(self, func, *args, **kwargs):
        try:
            out = func(*args, **kwargs)
        except Exception as err:
            self._message.value = f"error: {err}"
            raise
        return out

    def accept(self):
        """Accept the current frame's picks as its manual profile (saved atomically)."""
        fit = self._guard(self.session.accept, self.frame)
        self._message.value = f"frame {self.frame + 1}: manual profile saved (V = {fit.volume * 1e12:.4g} nL)"
        self.draw()
        return fit

    def clear(self):
        """Remove the current frame's picked points (the saved profile stays)."""
        self.session.clear_picks(self.frame)
        self._sync_points(self.frame)
        self.draw()

    def remove(self):
        """Delete the current frame's saved manual profile."""
        self._guard(self.session.remove_manual, self.frame)
        self._sync_points(self.frame)
        self._message.value = f"frame {self.frame + 1}: manual profile removed"
        self.draw()

    def semi_automatic(self):
        """Re-trace every frame guided by the picked frames (preview; see the session)."""
        self._guard(self.session.trace_with_priors)
        self._message.value = "traced with priors (preview: accept frames or re-run extraction to keep)"

    def keep_priors(self):
        """Save the picked frames as priors in the curation and re-trace with them."""
        self._guard(self.session.trace_with_priors, save=True)
        self._message.value = "picks kept as priors in curation.json; extraction re-run with them"
        self.draw()

    def reprocess(self):
        """Run the process step with the saved manual profiles and reload the automatic profiles."""
        self._guard(self.session.reprocess)
        self._message.value = "extraction updated"

    def set_rim(self):
        """Save the current frame's picked ends as the chamber's rim (curation.json): where the next extraction
        looks for the top face and walls when it does not find them by itself."""
        rim = self._guard(self.session.rim_from_picks, self.frame)
        self._guard(self.session.set_rim, rim)
        where = "" if self.frame == 0 else f" (picked on frame {self.frame + 1}: it is used in the first frame)"
        self._message.value = ("rim saved: ({:.1f}, {:.1f}) - ({:.1f}, {:.1f}) px".format(*rim) + where +
                               "; re-run extraction to use it")
        return rim

    def clear_rim(self):
        """Forget the rim saved in curation.json (experiment.toml's, if any, is used again)."""
        self._guard(self.session.set_rim, None)
        rim = self.session.rim()
        self._message.value = "rim cleared" + ("" if rim is None else
                                               "; experiment.toml's rim_px is used: ({:.1f}, {:.1f}) - "
                                               "({:.1f}, {:.1f}) px".format(*rim))

    def import_points(self, path):
        """Load points from a CSV or ImageJ ROI file, as they are (not snapped)."""
        frames = self._guard(self.session.import_points, path, snap=False)
        from osmobulge.plugins._logic import picks_to_layer_data

        self._updating = True
        try:
            self.points_layer.data = picks_to_layer_data(self.session.picks)
        finally:
            self._updating = False
        self._message.value = f"imported points on {len(frames)} frames"
        self.draw()
        return frames

    def export_points(self, path):
        """Write every frame's points to a CSV or ImageJ ROI file."""
        out = self._guard(self.session.export_points, path)
        self._message.value = f"wrote {out}"
        return out


def open_experiment(folder, viewer=None, *, frame: int | None = None):
    """Open an experiment folder in napari with both osmobulge widgets docked.

    Parameters
    ----------
    folder : path
        Experiment folder (with ``experiment.toml``).
    viewer : napari.Viewer, optional
        Default: a new viewer.
    frame : int, optional
        Frame to show first (default: the first frame).

    Returns
    -------
    viewer, curation_widget, profile_picker
    """
    import napari

    viewer = viewer or napari.Viewer()
    viewer.open(str(folder), plugin="osmobulge")
    cw, pp = CurationWidget(viewer), ProfilePicker(viewer)
    viewer.window.add_dock_widget(cw, name="Curation", area="right")
    viewer.window.add_dock_widget(pp, name="Profile picker", area="right", tabify=False)
    viewer.dims.set_current_step(0, int(frame or 0))
    return viewer, cw, pp
