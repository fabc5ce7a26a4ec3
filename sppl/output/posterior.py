"""The posterior of a run as arrays, as an ArviZ file, and its convergence diagnostics.

This is the one module that calls ArviZ (arviz-base to build the file, arviz-stats for R-hat
and ESS) and xarray; everything else asks it.

The file, ``run/posterior.nc``, is NetCDF4 in the ArviZ layout (groups ``posterior`` and
``sample_stats``, dimensions ``(chain, draw, ...)``), readable with
``xarray.open_datatree(path, engine="h5netcdf")`` or arviz 0.x ``az.from_netcdf(path)``.
A scene holds a varying number of objects, so objects are stored in ``slot``s padded to the
largest number any stored sample has: ``exists`` (1 or 0) says which slots hold an object, the
class is ``object_class``, and each parameter name of any class is one variable (NaN where the
slot is empty or the object's class has no such parameter). Every variable is a number, so that
``arviz_stats.summary(tree)`` takes the file as it is: a categorical one (``object_class``, a
colour) is an integer code, -1 in an empty slot, with its labels as a coordinate (``class``,
``<name>_label``) and the CF attributes ``flag_values`` and ``flag_meanings``. ``draw`` is the
sweep number of each draw, the same in every chain. Where the samples mark which objects some
camera sees (``sppl.render.seen``), ``seen`` (1 or 0) is that mark per slot, and ``n_seen`` and
``count_seen`` (per class) are the numbers seen. Slots are ordered by class (the model's
order), then x, then y. The order of objects means nothing (the scene is a set; slot 0 in one
draw need not be the same object as slot 0 in the next), so R-hat and ESS are computed only for
*label-invariant* quantities: the number of objects, the number of each class, the log joint,
the number seen, the log likelihood and the noise scales.
"""

from __future__ import annotations

import hashlib
import json
import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .._version import __version__
from ..errors import SpplError
from .samples import partial_reason, read_samples

POSTERIOR_FILE = "posterior.nc"


@dataclass
class Chain:
    folder: Path
    meta: dict[str, Any]
    summary: dict[str, Any]
    samples: list[dict[str, Any]]


@dataclass
class RunFiles:
    """A run folder as ``sppl sample`` leaves it: one chain in the folder itself, or several
    in ``chain_<i>/`` with the combined summary at the top."""

    folder: Path
    meta: dict[str, Any]
    summary: dict[str, Any]
    chains: list[Chain]

    @property
    def class_names(self) -> list[str]:
        return list(self.summary["class_counts"])

    @property
    def burn(self) -> int:
        return int(self.summary.get("burn", 0))


def _json(path: Path) -> dict[str, Any]:
    try:
        return json.loads(path.read_text())
    except FileNotFoundError:
        raise SpplError(
            f"{path}: missing; is {path.parent} a folder written by `sppl sample`?") from None
    except json.JSONDecodeError as e:
        raise SpplError(f"{path}:{e.lineno}:{e.colno}: not valid JSON: {e.msg}") from None


def load_run(folder: str | Path, *, summary: dict[str, Any] | None = None) -> RunFiles:
    """Read a run folder: its run.json, summary.json and every chain's samples."""
    folder = Path(folder)
    if not folder.is_dir():
        raise SpplError(f"{folder}: no such run folder")
    meta = _json(folder / "run.json")
    if summary is None:
        summary = _json(folder / "summary.json")
    if (folder / "samples.jsonl").exists():
        chain_folders = [folder]
    else:
        chain_folders = [folder / name for name in meta.get("chain_folders", [])]
        chain_folders = [f for f in chain_folders if (f / "samples.jsonl").exists()]
    if not chain_folders:
        raise SpplError(f"{folder}: no samples.jsonl, neither in it nor in chain_<i>/ folders")
    chains = []
    for f in chain_folders:
        chain_meta = meta if f == folder else _json(f / "run.json")
        chain_summary = summary if f == folder else _json(f / "summary.json")
        chains.append(Chain(f, chain_meta, chain_summary, read_samples(f / "samples.jsonl")))
    return RunFiles(folder, meta, summary, chains)


# ----------------------------------------------------------------------------------------------
# Arrays


@dataclass
class Posterior:
    """Posterior draws as arrays with leading dimensions (chain, draw)."""

    variables: dict[str, np.ndarray]
    dims: dict[str, list[str]]
    coords: dict[str, list]
    stats: dict[str, np.ndarray]
    attrs: dict[str, Any] = field(default_factory=dict)
    class_names: list[str] = field(default_factory=list)
    noise_names: list[str] = field(default_factory=list)

    @property
    def n_chains(self) -> int:
        return self.variables["n_objects"].shape[0]

    @property
    def n_draws(self) -> int:
        return self.variables["n_objects"].shape[1]


def _slot_key(class_index: dict[str, int]):
    def key(o: dict[str, Any]):
        p = o["params"]
        return (class_index.get(o["class"], len(class_index)),
                float(p.get("x", 0.0)) if isinstance(p.get("x", 0.0), (int, float)) else 0.0,
                float(p.get("y", 0.0)) if isinstance(p.get("y", 0.0), (int, float)) else 0.0)

    return key


def kept_samples(run: RunFiles, burn: int | None = None) -> list[list[dict[str, Any]]]:
    """Each chain's samples after burn-in (step >= burn, as the summary counts them)."""
    burn = run.burn if burn is None else burn
    return [[s for s in c.samples if s["step"] >= burn] for c in run.chains]


def posterior_arrays(run: RunFiles, burn: int | None = None) -> Posterior:
    """The stored samples after burn-in as arrays, every chain cut to the shortest one's
    number of draws (ArviZ needs a rectangle)."""
    per_chain = [k for k in kept_samples(run, burn) if k]
    if not per_chain:
        raise SpplError(f"{run.folder}: no samples after the burn-in of {run.burn} steps")
    # The draws are the sweeps every chain has (a chain stopped early has fewer), so that a
    # draw is one sweep number across chains: the file's draw coordinate.
    common = set.intersection(*({s["step"] for s in k} for k in per_chain))
    per_chain = [[s for s in k if s["step"] in common] for k in per_chain]
    n_draws = len(common)
    if n_draws == 0 or any(len(k) != n_draws for k in per_chain):
        raise SpplError(f"{run.folder}: the chains' samples share no sweep numbers, or repeat "
                        "one (was the folder written by two runs at once?)")
    n_chains = len(per_chain)
    classes = run.class_names
    class_index = {c: i for i, c in enumerate(classes)}
    n_slots = max(1, max(len(s["objects"]) for k in per_chain for s in k))
    # Parameter names over all classes, in first-seen order; categorical if any value is text.
    params: dict[str, bool] = {}
    for k in per_chain:
        for s in k:
            for o in s["objects"]:
                for name, v in o["params"].items():
                    params[name] = params.get(name, False) or isinstance(v, str)
    noise_names = [f"{kind}_{name}" for kind, ps in per_chain[0][0]["noise"].items() for name in ps]

    shape, slots = (n_chains, n_draws), (n_chains, n_draws, n_slots)
    n_objects = np.zeros(shape, dtype=np.int64)
    count = np.zeros((*shape, len(classes)), dtype=np.int64)
    exists = np.zeros(slots, dtype=bool)
    object_class = np.full(slots, "", dtype=f"<U{max([1, *map(len, classes)])}")
    values = {
        name: (np.full(slots, "", dtype=object) if cat else np.full(slots, np.nan))
        for name, cat in params.items()
    }
    noise = {n: np.full(shape, np.nan) for n in noise_names}
    # Which objects some camera sees (sppl.render.seen), where every sample marks them.
    marked = all("seen" in o for k in per_chain for s in k for o in s["objects"])
    seen = np.zeros(slots, dtype=bool)
    n_seen = np.zeros(shape, dtype=np.int64)
    count_seen = np.zeros((*shape, len(classes)), dtype=np.int64)
    lp, loglik, step = np.zeros(shape), np.zeros(shape), np.zeros(shape, dtype=np.int64)
    key = _slot_key(class_index)
    for c, k in enumerate(per_chain):
        for d, s in enumerate(k):
            objs = sorted(s["objects"], key=key)
            n_objects[c, d] = len(objs)
            lp[c, d], loglik[c, d], step[c, d] = s["score"], s["log_likelihood"], s["step"]
            for kind, ps in s["noise"].items():
                for name, v in ps.items():
                    if f"{kind}_{name}" in noise:
                        noise[f"{kind}_{name}"][c, d] = v
            for j, o in enumerate(objs):
                exists[c, d, j] = True
                object_class[c, d, j] = o["class"]
                if o["class"] in class_index:
                    count[c, d, class_index[o["class"]]] += 1
                if marked and o["seen"]:
                    seen[c, d, j] = True
                    n_seen[c, d] += 1
                    if o["class"] in class_index:
                        count_seen[c, d, class_index[o["class"]]] += 1
                for name, v in o["params"].items():
                    values[name][c, d, j] = v
    for name, cat in params.items():
        if cat:
            width = max([1, *(len(v) for v in values[name].ravel())])
            values[name] = values[name].astype(f"<U{width}")
    reserved = {"n_objects", "count", "exists", "object_class", "seen", "n_seen", "count_seen",
                *noise_names}
    variables: dict[str, np.ndarray] = {
        "n_objects": n_objects, "count": count, **noise, "exists": exists,
        "object_class": object_class,
    }
    dims = {"count": ["class"], "exists": ["slot"], "object_class": ["slot"]}
    if marked:
        variables.update(n_seen=n_seen, count_seen=count_seen, seen=seen)
        dims.update(count_seen=["class"], seen=["slot"])
    for name, arr in values.items():
        var = f"param_{name}" if name in reserved else name
        variables[var] = arr
        dims[var] = ["slot"]
    return Posterior(
        variables=variables,
        dims=dims,
        coords={"class": classes, "slot": list(range(n_slots)),
                "draw": [int(x) for x in step[0]]},
        stats={"lp": lp, "log_likelihood": loglik, "step": step},
        attrs=_attrs(run, n_chains, n_draws),
        class_names=classes,
        noise_names=noise_names,
    )


def _attrs(run: RunFiles, n_chains: int, n_draws: int) -> dict[str, Any]:
    meta = run.meta
    attrs: dict[str, Any] = {
        "sppl_version": __version__,
        "sampled_with": meta.get("sppl_version"),
        # An integer NetCDF stores (a 64-bit one), or the record as JSON text.
        "seed": (meta.get("seed") if isinstance(meta.get("seed"), int)
                 and 0 <= meta["seed"] < 2**63 else json.dumps(meta.get("seed"))),
        "chains": n_chains,
        "draws_per_chain": n_draws,
        "steps": meta.get("steps"),
        "thin": meta.get("thin"),
        "burn": run.burn,
        "model": meta.get("model"),
        "observations": meta.get("observations"),
        "gl_renderer": meta.get("gl_renderer") or run.chains[0].meta.get("gl_renderer"),
        "run_folder": str(run.folder),
        "slots": "objects padded to slots; `exists` marks real ones; slot order is not identity",
        # The summary's mark, when too few samples were left after burn-in (sppl.output.samples).
        "partial": partial_reason(n_chains * n_draws, run.burn),
    }
    model = meta.get("model")
    if model and Path(model).is_file():
        attrs["model_sha256"] = hashlib.sha256(Path(model).read_bytes()).hexdigest()
    return {k: v for k, v in attrs.items() if v is not None}


# ----------------------------------------------------------------------------------------------
# The ArviZ file


def to_datatree(post: Posterior):
    """The posterior as an ``xarray.DataTree`` in the ArviZ layout (via arviz-base).

    Every variable of the file is a number, so that ArviZ's functions take the whole group
    (``arviz_stats.summary(tree)``): ``exists`` is 0 or 1, and a categorical variable (the
    class of a slot's object, a colour) is an integer code, -1 in an empty slot, whose labels
    are the coordinate ``class`` for ``object_class`` and ``<name>_label`` for a parameter,
    and the CF attributes ``flag_values`` and ``flag_meanings``. ``draw`` is the sweep number."""
    import arviz_base
    import xarray as xr

    variables = dict(post.variables)
    flags: dict[str, tuple[list[int], list[str]]] = {"exists": ([0, 1], ["empty", "object"])}
    variables["exists"] = variables["exists"].astype(np.int8)
    if "seen" in variables:
        flags["seen"] = ([0, 1], ["unseen", "seen"])
        variables["seen"] = variables["seen"].astype(np.int8)
    for name, values in post.variables.items():
        if values.dtype.kind != "U":
            continue
        labels = (list(post.class_names) if name == "object_class"
                  else sorted(set(values.ravel()) - {""}))
        codes = np.full(values.shape, -1, dtype=np.int16)
        for i, label in enumerate(labels):
            codes[values == label] = i
        variables[name] = codes
        flags[name] = (list(range(len(labels))), labels)
    tree = arviz_base.from_dict(
        {"posterior": variables, "sample_stats": post.stats},
        dims=post.dims,
        coords=post.coords,
        attrs={"/": post.attrs},
    )
    group = tree["posterior"].to_dataset()
    for name, (values, labels) in flags.items():
        group[name].attrs.update(flag_values=np.array(values, dtype=np.int16),
                                 flag_meanings=" ".join(labels))
        if name not in ("exists", "object_class"):  # object_class's labels: the class coordinate
            group = group.assign_coords({f"{name}_label": labels})
    tree["posterior"] = xr.DataTree(group)
    return tree


def write_posterior(folder: str | Path, out: str | Path | None = None, *,
                    run: RunFiles | None = None) -> Path:
    """Write ``folder/posterior.nc`` (or ``out``) from a run folder's samples."""
    run = run or load_run(folder)
    out = Path(out) if out is not None else Path(folder) / POSTERIOR_FILE
    tree = to_datatree(posterior_arrays(run))
    if out.is_dir() or (out.exists() and not _is_netcdf4(out)):
        raise SpplError(f"{out}: exists and is not a posterior file, so it is not replaced",
                        hint="choose another --out")
    try:
        if out.exists():
            out.unlink()
        tree.to_netcdf(out, engine="h5netcdf")
    except OSError as e:
        raise SpplError(f"{out}: cannot write the posterior file ({e.strerror or e})",
                        hint="check that its folder exists and can be written") from None
    return out


def _is_netcdf4(path: Path) -> bool:
    """Whether ``path`` is an HDF5 file (NetCDF4 is HDF5), or empty: one export may replace."""
    try:
        with open(path, "rb") as f:
            head = f.read(8)
    except OSError:
        return False
    return head in (b"", b"\x89HDF\r\n\x1a\n")


def open_posterior(path: str | Path):
    """Read a posterior file back as an ``xarray.DataTree``."""
    import xarray as xr

    return xr.open_datatree(path, engine="h5netcdf")


# ----------------------------------------------------------------------------------------------
# Diagnostics


def invariant_quantities(post: Posterior) -> dict[str, np.ndarray]:
    """The label-invariant quantities, each (chain, draw): what R-hat and ESS are computed on."""
    out = {"n_objects": post.variables["n_objects"].astype(float)}
    for i, c in enumerate(post.class_names):
        out[f"count[{c}]"] = post.variables["count"][..., i].astype(float)
    if "n_seen" in post.variables:
        out["n_seen"] = post.variables["n_seen"].astype(float)
    out["log joint"] = post.stats["lp"]
    out["log likelihood"] = post.stats["log_likelihood"]
    for n in post.noise_names:
        out[n] = post.variables[n]
    return out


def _finite(x: Any) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


def diagnostics(post: Posterior) -> dict[str, dict[str, float | None]]:
    """Rank-normalised split R-hat and bulk and tail ESS (Vehtari et al. 2021, computed by
    arviz-stats) of each label-invariant quantity, with its mean and sd. R-hat needs two
    chains or more (None otherwise); a quantity that never changes has None for all three."""
    import arviz_stats

    def ess(a, method):
        try:
            if method == "tail":
                return arviz_stats.ess(a, chain_axis=0, draw_axis=1, method="tail",
                                       prob=(0.05, 0.95))
            return arviz_stats.ess(a, chain_axis=0, draw_axis=1, method=method)
        except TypeError:  # arviz-stats 1.x takes no prob for the tail ESS
            return arviz_stats.ess(a, chain_axis=0, draw_axis=1, method=method)

    out = {}
    with warnings.catch_warnings(), np.errstate(all="ignore"):
        warnings.simplefilter("ignore", RuntimeWarning)
        for name, a in invariant_quantities(post).items():
            constant = bool(np.all(a == a.flat[0]))
            enough = a.shape[1] >= 4
            out[name] = {
                "mean": float(np.mean(a)),
                "sd": float(np.std(a)),
                "rhat": None if constant or not enough or a.shape[0] < 2 else _finite(
                    arviz_stats.rhat(a, chain_axis=0, draw_axis=1)),
                "ess_bulk": None if constant or not enough else _finite(ess(a, "bulk")),
                "ess_tail": None if constant or not enough else _finite(ess(a, "tail")),
            }
    return out
