"""The result as stored in a .blend: one owner of its layout (no bpy).

A solve produces a sequence of configurations (the error curve, paper Fig. 11).
:class:`StoredResult` holds everything needed to re-apply any of them later, without the engine:
the whole curve (for the chart), and for the configurations kept re-appliable (every one up to
STORE_ALL_UP_TO lights, ~STORE_LOG_POINTS log-spaced above, e_x and the final one) each light's
strength and every patch's radiosity; the lights (object, kind, area, centre, normal, polygons),
their cells' triangles and reflectance, the patches -> polygons weights, and (direct mode) the
scene's lamps that are lights (``lamps``, ``light_lamp``: what each was). The solve builds it
(``StoredResult.from_solve``), results.py writes and reads it (``pack`` / ``unpack``: one string,
zlib-compressed npz in base64, kept in the scene's custom property ``relight_result``).
Floating-point arrays are stored as float32: no loss of range (float16 overflowed above
65,504 W/m^2), 7 significant digits. Non-finite values are refused when packing.
"""
from __future__ import annotations

import base64
import dataclasses
import io
import json
import zlib
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from ..engine.options import STORE_ALL_UP_TO, STORE_LOG_POINTS

FORMAT = 2


@dataclass
class StoredResult:
    """Per light (n_lights): ``light_*``; per light-cell patch (|C|): ``cell_*``; per kept point
    (K): ``n_lights``, ``error``, ``relative_error``, ``n_negative``, ``exitance`` (K, n_lights, 3)
    W/m^2 (the lights' strength), ``radiosity`` (K, P, 3) W/m^2; per curve point: ``curve_*``
    (``curve_bound_relative_error`` -1 where there is no certificate). ``meta``: command, options,
    fingerprints (JSON)."""

    objects: list
    polygon_offset: np.ndarray
    light_object: np.ndarray
    light_kind: np.ndarray
    light_area: np.ndarray
    light_center: np.ndarray
    light_normal: np.ndarray
    light_polygons_indptr: np.ndarray
    light_polygons: np.ndarray
    basis_indptr: np.ndarray
    basis_indices: np.ndarray
    cell_triangles: np.ndarray
    cell_triangle_cell: np.ndarray
    cell_normal: np.ndarray
    cell_patch: np.ndarray
    cell_reflectance: np.ndarray
    polygon_weights_indptr: np.ndarray
    polygon_weights_patch: np.ndarray
    polygon_weights: np.ndarray
    curve_n_lights: np.ndarray
    curve_error: np.ndarray
    curve_relative_error: np.ndarray
    curve_n_negative: np.ndarray
    curve_power: np.ndarray
    curve_bound_relative_error: np.ndarray
    point_index: np.ndarray
    n_lights: np.ndarray
    error: np.ndarray
    relative_error: np.ndarray
    n_negative: np.ndarray
    exitance: np.ndarray
    radiosity: np.ndarray
    final: np.ndarray
    target_patch: np.ndarray
    target_value: np.ndarray
    target_norm: np.ndarray
    meta: dict = field(default_factory=dict)
    #: the lights that are lamps, as the solve saw them (their kind's ``record``, engine/lights/kind.py: the scene's lamps of a
    #: reduction, as the user set them), and per light the lamp it is (index into ``lamps``; -1 for a
    #: surface light). Results written before lamps were lights have neither (read as no lamp).
    lamps: list = field(default_factory=list)
    light_lamp: np.ndarray = None
    #: every patch's reflectance (P, 3), as the solve modelled it: the illuminance view reads
    #: E = (B - e) / reflectance from it (pipeline/false_colour.py). Results written before it was
    #: kept have none (None).
    patch_reflectance: np.ndarray = None

    # -- building ----------------------------------------------------------------------------
    @classmethod
    def from_solve(cls, model, red, curve, report: dict) -> "StoredResult":
        """From the solve's stages (jobs.Model, the ReductionResult, jobs.Curve) and its report."""
        from .report import json_safe, row_panels

        keep, pts = curve.keep, red.curve
        lights, patches, pmap = model.lights, model.patches, curve.polygons
        C = lights.patches
        in_c = np.full(patches.n_patches, -1)
        in_c[C] = np.arange(len(C))
        cell_of_tri = in_c[patches.tri_patch]
        sel = np.flatnonzero(cell_of_tri >= 0)
        sel = sel[np.argsort(cell_of_tri[sel], kind="stable")]
        W = pmap.weights.tocsr()
        lp = curve.light_polygons
        basis_csc = lights.basis.tocsc()
        first = basis_csc.indptr[:-1]
        has_patch = np.diff(basis_csc.indptr) > 0  # a lamp has none
        light_object = np.full(lights.n_lights, -1, dtype=np.int64)
        light_object[has_patch] = model.patches.object[C[basis_csc.indices[first[has_patch]]]]
        light_lamp = np.full(lights.n_lights, -1, dtype=np.int64)
        lamps = []
        for j in range(lights.n_lights):
            lamp = lights.lamp(j)
            if lamp is not None:
                light_lamp[j] = len(lamps)
                lamps.append(lamp.kind.record(lamp))
        return cls(
            objects=list(model.faces.object_names),
            polygon_offset=pmap.offset,
            light_object=light_object,
            light_kind=lights.kind, light_area=lights.area, light_center=lights.center,
            light_normal=lights.normal, light_polygons_indptr=lp.indptr, light_polygons=lp.indices,
            basis_indptr=lights.basis.indptr, basis_indices=lights.basis.indices,
            cell_triangles=patches.tri_vertices[sel].astype(np.float32),
            cell_triangle_cell=cell_of_tri[sel], cell_normal=patches.normal[C], cell_patch=C,
            cell_reflectance=patches.reflectance[C],
            polygon_weights_indptr=W.indptr, polygon_weights_patch=W.indices, polygon_weights=W.data,
            curve_n_lights=np.array([p.n_lights for p in pts]),
            curve_error=np.array([p.error for p in pts]),
            curve_relative_error=np.array([p.relative_error for p in pts]),
            curve_n_negative=np.array([p.n_negative for p in pts]),
            curve_power=np.array([c["power"] for c in report["curve"]]),
            curve_bound_relative_error=np.array([-1.0 if c["bound_relative_error"] is None else
                                                 c["bound_relative_error"] for c in report["curve"]]),
            point_index=keep,
            n_lights=np.array([pts[i].n_lights for i in keep]),
            error=np.array([pts[i].error for i in keep]),
            relative_error=np.array([pts[i].relative_error for i in keep]),
            n_negative=np.array([pts[i].n_negative for i in keep]),
            exitance=curve.exitance,
            radiosity=curve.radiosity,
            final=np.array(red.final_index),
            target_patch=model.problem.targets,  # the painted patches and their painted radiosity (W/m^2)
            target_value=patches.target_radiosity[model.problem.targets],
            target_norm=np.array(model.problem.target_norm),
            meta={"command": report["command"], "options": json_safe(report["options"]),
                  "light_colour": json_safe(report.get("light_colour") or {"mode": "free"}),
                  "rows": row_panels(model, curve)},
            lamps=lamps, light_lamp=light_lamp, patch_reflectance=patches.reflectance,
        )

    def with_fingerprints(self, fingerprints) -> "StoredResult":
        """A copy whose meta holds the exported meshes' fingerprints (checked before applying)."""
        return dataclasses.replace(self, meta=dict(self.meta, fingerprints=fingerprints or {}))

    # -- derived -----------------------------------------------------------------------------
    def light_basis(self) -> sp.csr_matrix:
        """(|C|, n_lights) 0/1: the light cells of each light."""
        return sp.csr_matrix((np.ones(len(self.basis_indices)), self.basis_indices, self.basis_indptr),
                             shape=(len(self.cell_normal), len(self.light_area)))

    def polygon_weight_matrix(self) -> sp.csr_matrix:
        """(n_polygons, P): per polygon, the area fractions of the patches its triangles lie on."""
        return sp.csr_matrix((self.polygon_weights, self.polygon_weights_patch, self.polygon_weights_indptr),
                             shape=(int(self.polygon_offset[-1]), int(self.radiosity.shape[1])))

    # -- the string in the .blend ------------------------------------------------------------
    def _stored_fields(self) -> tuple:
        """(arrays, JSON texts): the fields as the text keeps them, the floating-point arrays in
        float32 (non-finite values refused), ``light_lamp`` -1 for no lamp (pack, as_stored)."""
        arrays = {f.name: np.asarray(getattr(self, f.name)) for f in dataclasses.fields(self)
                  if f.name not in _JSON and not (f.name in _OPTIONAL and getattr(self, f.name) is None)}
        if self.light_lamp is None:
            arrays["light_lamp"] = np.full(len(self.light_area), -1, dtype=np.int64)
        for k, a in arrays.items():
            if a.dtype.kind == "f":
                if not np.all(np.isfinite(a)):
                    raise ValueError(f"refusing to store non-finite values ({k})")
                a32 = a.astype(np.float32)
                if not np.all(np.isfinite(a32)):
                    raise ValueError(f"values of {k} exceed the float32 range")
                arrays[k] = a32
        return arrays, {name: json.dumps(getattr(self, name) or _JSON[name]()) for name in _JSON}

    def pack(self) -> str:
        return self._pack(*self._stored_fields())

    def pack_and_view(self) -> tuple:
        """(``pack()``, ``as_stored()``), the stored fields converted once for both."""
        arrays, texts = self._stored_fields()
        return self._pack(dict(arrays), texts), self._view(arrays, texts)

    def _pack(self, arrays, texts) -> str:
        buf = io.BytesIO()
        for name, text in texts.items():
            arrays[name + "_json"] = np.frombuffer(text.encode(), dtype=np.uint8)
        arrays["format"] = np.array(FORMAT)
        np.savez(buf, **arrays)
        # (level 1: the living room's 1.47 MB of arrays to 49.9 %, 48.5 % at 6, in 0.68 of its time)
        return base64.b64encode(zlib.compress(buf.getvalue(), 1)).decode("ascii")

    def as_stored(self) -> "StoredResult":
        """What ``unpack(pack())`` gives, without the round trip (the result just stored, shown at
        once: Live writes one at every stroke): the fields as ``pack`` stores them, the JSON ones
        read back."""
        return self._view(*self._stored_fields())

    def _view(self, arrays, texts) -> "StoredResult":
        out = {k: a if a.dtype.kind == "f" else a.copy() for k, a in arrays.items()}  # (float32: new arrays)
        out.update({name: json.loads(text) for name, text in texts.items()})
        return type(self)(**out)

    @classmethod
    def unpack(cls, text: str) -> "StoredResult":
        raw = zlib.decompress(base64.b64decode(text.encode("ascii")))
        with np.load(io.BytesIO(raw)) as z:
            out = {k: z[k] for k in z.files}
        if int(out.pop("format")) != FORMAT:
            raise ValueError("this file's Relight result was written by an incompatible version")
        for name in _JSON:
            if name + "_json" in out:
                out[name] = json.loads(out.pop(name + "_json").tobytes().decode())
        if "lamps" not in out and "light_area" in out:  # written before lamps were lights: no lamp
            out["lamps"] = []
            out["light_lamp"] = np.full(len(out["light_area"]), -1, dtype=np.int64)
        names = {f.name for f in dataclasses.fields(cls)}
        missing = names - set(out) - _OPTIONAL
        if missing:
            raise ValueError(f"this file's Relight result lacks {', '.join(sorted(missing))}")
        return cls(**{k: v for k, v in out.items() if k in names})


#: the fields kept as JSON, and their empty value
_JSON = {"objects": list, "meta": dict, "lamps": list}
#: the array fields a result written by an earlier version may lack (None: not stored)
_OPTIONAL = {"patch_reflectance"}


def stored_points(n_lights, final_index):
    """Indices of the curve points kept re-appliable (see STORE_ALL_UP_TO), ascending."""
    n = np.asarray(n_lights)
    keep = n <= STORE_ALL_UP_TO
    if len(n) and n.max() > STORE_ALL_UP_TO:
        wanted = np.unique(np.rint(np.geomspace(STORE_ALL_UP_TO + 1, n.max(), STORE_LOG_POINTS)))
        for w in wanted:  # the point closest to each wanted count
            keep[int(np.argmin(np.abs(n - w)))] = True
    keep[0] = True  # e_x (or the first configuration)
    keep[final_index] = True
    return np.flatnonzero(keep)
