"""Toolbox-style summaries and truth comparison tables of the calibration results."""
from __future__ import annotations

import numpy as np


# ============================================================== result formatting
def _f(values, sep="   "):
    return sep.join(f"{v:3.5f}" for v in np.asarray(values, dtype=np.float64).ravel())


def _kc_line(kc):
    kc = np.asarray(kc, dtype=np.float64)
    return f"{_f(kc[:4])}  {kc[4]:5.5f}"


def _intrinsics_block(cam, unc, s, pm):
    """The toolbox's four intrinsic lines; ``s`` is "" or the "_left"/"_right" suffix."""
    fcn, ccn, alp, kcn = f"fc{s}", f"cc{s}", f"alpha_c{s}", f"kc{s}"
    a, ae = cam.alpha_c, float(np.asarray(unc["alpha_c"]).ravel()[0])
    lines = [
        f"Focal Length:          {fcn} = [ {_f(cam.fc)} ] {pm} [ {_f(unc['fc'])} ]",
        f"Principal point:       {ccn} = [ {_f(cam.cc)} ] {pm} [ {_f(unc['cc'])} ]",
        f"Skew:             {alp} = [ {a:3.5f} ] {pm} [ {ae:3.5f}  ]   => angle of pixel axes = "
        f"{90 - np.degrees(np.arctan(a)):3.5f} {pm} {np.degrees(np.arctan(ae)):3.5f} degrees",
        f"Distortion:            {kcn} = [ {_kc_line(cam.kc)} ] {pm} [ {_kc_line(unc['kc'])} ]",
    ]
    return lines


def _rejected_lines(rejected):
    """One ``  rejected <name>: <why>`` line per rejected view or pair (summary tails)."""
    return [f"  rejected {name}: {why}" for name, why in rejected.items()]


def _select(indices, names, what):
    if indices is None:
        return set()
    if isinstance(indices, (int, np.integer, str)):
        indices = [indices]
    out = set()
    for v in indices:
        if isinstance(v, str):
            if v not in names:
                raise ValueError(f"{what} {v!r} is not one of {list(names)}")
            out.add(names.index(v))
        else:
            k = int(v)
            if not -len(names) <= k < len(names):
                raise ValueError(f"{what} index {k} out of range for {len(names)} views")
            out.add(k % len(names))
    return out


def _frozen(a):
    if a is None:
        return None
    a = np.array(a, dtype=np.float64)
    a.setflags(write=False)
    return a


def _truth_table(entries):
    """DataFrame of (parameter, estimate, truth, three_sigma) rows with error and sigma units."""
    import pandas as pd

    rows = []
    for name, est, true, unc in entries:
        est, true, unc = (np.atleast_1d(np.asarray(v, dtype=np.float64)).ravel() for v in (est, true, unc))
        for k in range(est.size):
            label = name if est.size == 1 else f"{name}[{k}]"
            rows.append((label, est[k], true[k], unc[k] if k < unc.size else np.nan))
    df = pd.DataFrame(rows, columns=["parameter", "estimate", "truth", "three_sigma"])
    df["error"] = df["estimate"] - df["truth"]
    with np.errstate(divide="ignore", invalid="ignore"):
        df["error_in_sigma"] = 3.0 * df["error"] / df["three_sigma"]
    df["inside_3sigma"] = df["error"].abs() <= df["three_sigma"]
    return df[["parameter", "estimate", "truth", "error", "three_sigma", "error_in_sigma", "inside_3sigma"]]


def _camera_entries(cam, true, unc, suffix=""):
    return [
        (f"fc{suffix}", cam.fc, true.fc, unc[f"fc{suffix}"]),
        (f"cc{suffix}", cam.cc, true.cc, unc[f"cc{suffix}"]),
        (f"alpha_c{suffix}", cam.alpha_c, true.alpha_c, unc[f"alpha_c{suffix}"]),
        (f"kc{suffix}", cam.kc, true.kc, unc[f"kc{suffix}"]),
    ]
