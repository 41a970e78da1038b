"""The bond on Σ (``[interface]``): validation runs, a function per case returning its numbers.

- :func:`stiff_limit`: the elastic law on Example 2 (``full-opening``) against the rigid bond as the stiffness
  grows (the energy's difference falls as 1/k), by ``schur`` and ``mprgp`` (the same discrete problem solved
  two ways: on rank 0 from the Schur complements, and by rounds of block solves);
- :func:`bilinear_methods`: the bilinear law in one load step by ``schur`` (Newton's method) and ``mprgp`` (the
  secant fixed point), against each other;
- :func:`enf_growth`: the ENF (mode II under three-point bending) with the bilinear law under Benzeggagh–Kenane
  against the Griffith growth of the same structure with G_IIc, as :func:`dcb_growth`;
- :func:`dcb_growth`: a displacement-controlled DCB (two identical layers, plane strain, E = 200, arms h = 1)
  grown with the bilinear law (strength 0.005 E, toughness G_c) against the Griffith growth of the same
  structure with the rigid bond (``ddsolve grow`` with ``[fracture] toughness = G_c``, the same mesh): the load
  before damage against the linear curve, and the load once the crack grows against the Griffith load at the
  same opening (interpolated along the Griffith run's stable branch).

``python -m experiments.cohesive`` prints them.  Nothing in ``ddsolve/`` imports this module.
"""
from __future__ import annotations

import math
import tempfile
import time
from pathlib import Path

import numpy as np

from experiments import delamination as beams

#: The DCB: length, arm thickness, initial crack, E, ν (both layers), the strength σ_c = 0.005 E and G_c.
LENGTH, ARM, CRACK, MODULUS, POISSON = 12.0, 1.0, 4.0, 200.0, 0.28
STRENGTH, TOUGHNESS = 0.005 * MODULUS, 2e-3
#: The uniform P2 mesh's size.
SIZE = 0.1
LAYERS = ("layer1", "layer2")
#: The ENF: half span L, initial crack a (a/L = 0.9 > 0.69: stable growth under the deflection), G_IIc, η, the
#: shear strength over the normal one (√(G_IIc/G_Ic): both modes' softening starts at one opening under one
#: stiffness, Turon et al. 2007), the loading nose's width, the uniform P2 mesh's size.
ENF_HALF_SPAN, ENF_CRACK, G_IIC, ETA = 10.0, 9.0, 4e-3, 2.0
SHEAR_RATIO = math.sqrt(G_IIC / TOUGHNESS)
NOSE, ENF_SIZE = 0.02, 0.2
#: The ENF runs' deflection (the crack passes the loading nose at L), the bond's steps to it (at most
#: ENF_LIMIT/ENF_STEPS, halved where damage moves fast) and Griffith's.
ENF_LIMIT, ENF_STEPS, ENF_GRIFFITH_STEPS = 0.32, 16, 32


def dcb_scene(bond: bool, size: float = SIZE, toughness: float = TOUGHNESS, strength: float = STRENGTH,
              crack: float = CRACK):
    """The DCB under a unit opening (±1/2 on both layers' left end faces of the arms), clamped on the right, on a
    uniform P2 mesh of ``size``, its initial crack (0, ``crack``); with no crack the end faces' outer halves are
    opened (the whole faces would meet at Σ's glued end). With the bilinear bond of ``strength`` (``bond``) or
    the Griffith toughness."""
    pieces = {"clamped": [("right", -ARM, ARM)], "opened_upper": [("left", 0.5 * ARM, ARM)],
              "opened_lower": [("left", -ARM, -0.5 * ARM)]}
    opened = ("left_upper", "left_lower") if crack > 0 else ("opened_upper", "opened_lower")
    cracks = [(0.0, crack)] if crack > 0 else []
    geo = beams.strip_geo(LENGTH, ARM, cracks, pieces if crack <= 0 else {"clamped": pieces["clamped"]})
    displacements = "".join(f"[displacements.{layer}.{face}]\ny = {value}\n" for layer in LAYERS
                            for face, value in zip(opened, (0.5, -0.5)))
    law = (f'[interface]\nlaw = "bilinear"\nstrength = {strength!r}\ntoughness = {toughness!r}\n' if bond else
           f"[fracture]\ntoughness = {toughness!r}\n")
    return written(f"dcb-{'bond' if bond else 'griffith'}", geo, displacements + law, size)


def enf_scene(bond: bool, size: float = ENF_SIZE, strength: float = STRENGTH):
    """The ENF (span 2L, arms h, the crack (0, a) from the roller's end; :data:`ENF_HALF_SPAN`, :data:`ENF_CRACK`)
    under a unit midspan deflection (a nose ``NOSE`` wide moved by −1, both layers), a pin at the right end's Σ
    and rollers under the left end face's lower part and the right one's, on a uniform P2 mesh of ``size``.
    With the bilinear bond under Benzeggagh–Kenane (``bond``: σ_c = ``strength``, τ_c = SHEAR_RATIO σ_c,
    G_Ic = TOUGHNESS, G_IIc, η = ETA) or Griffith's toughness G_IIc (the ENF's crack grows in mode II)."""
    middle = ENF_HALF_SPAN
    pieces = {"pin": [("right", -0.02 * ARM, 0.02 * ARM)], "roller": [("left", -ARM, -0.1 * ARM)],
              "load": [("top", middle - 0.5 * NOSE, middle + 0.5 * NOSE)]}
    geo = beams.strip_geo(2.0 * ENF_HALF_SPAN, ARM, [(0.0, ENF_CRACK)], pieces)
    held = {"roller": "y = 0.0", "right_lower": "y = 0.0", "pin": "x = 0.0\ny = 0.0", "load": "y = -1.0"}
    displacements = "".join(f"[displacements.{layer}.{name}]\n{body}\n" for layer in LAYERS
                            for name, body in held.items())
    law = (f'[interface]\nlaw = "bilinear"\nstrength = {strength!r}\ntoughness = {TOUGHNESS!r}\n'
           f'mode_mix = "benzeggagh-kenane"\nG_IIc = {G_IIC!r}\neta = {ETA!r}\n'
           f"shear_strength = {SHEAR_RATIO * strength!r}\n" if bond else f"[fracture]\ntoughness = {G_IIC!r}\n")
    return written(f"enf-{'bond' if bond else 'griffith'}", geo, displacements + law, size)


def written(name: str, geo: str, conditions: str, size: float):
    """The scene ``name`` of two identical layers on the strip ``geo`` (a uniform P2 mesh of ``size``) with
    ``conditions`` (its displacements and its law, scene text), written with its .geo to a new folder (for the
    command line: ``ddsolve grow FOLDER/NAME.toml --to F``) and loaded, solved by schur."""
    from ddsolve.problem import scene as scenes

    folder = Path(tempfile.mkdtemp(prefix="cohesive-"))
    (folder / f"{name}.geo").write_text(geo)
    materials = "".join(f"[materials.{layer}]\nE = {MODULUS}\nnu = {POISSON}\n" for layer in LAYERS)
    text = (f'title = "{name}"\n[mesh]\nfile = "{name}.geo"\nsize = {size!r}\ndegree = 2\n{materials}{conditions}'
            '[solver]\nmethod = "schur"\n')
    (folder / f"{name}.toml").write_text(text)
    return scenes.loads(text, origin=name, base=folder)


def stiff_limit(stiffnesses=(1e3, 1e5, 1e7, 1e9)) -> list[dict]:
    """The elastic law on ``full-opening`` against the rigid bond: per stiffness and method the energy, its
    relative difference from the rigid bond's, and the methods' difference."""
    import ddsolve

    rows = []
    for method in ("schur", "mprgp"):
        scene = ddsolve.Scene.load("full-opening", [f'solver.method="{method}"'])
        rigid = float(ddsolve.solve(scene, progress=lambda line: None).attrs["energy"])
        for k in stiffnesses:
            result = ddsolve.solve(scene.with_(['interface.law="elastic"', f"interface.stiffness={k!r}"]),
                                   progress=lambda line: None)
            energy = float(result.attrs["energy"])
            rows.append({"method": method, "stiffness": k, "energy": energy, "rigid": rigid,
                         "difference": abs(energy - rigid) / abs(rigid), "iterations": result.iterations})
    by = {(row["method"], row["stiffness"]): row["energy"] for row in rows}
    for row in rows:
        row["methods_differ"] = abs(by["schur", row["stiffness"]] - by["mprgp", row["stiffness"]]) / abs(row["energy"])
    return rows


def bilinear_methods(strength: float = 0.002, toughness: float = 1e-6) -> dict:
    """The bilinear law on ``full-opening`` in one load step by ``schur`` (Newton's method on rank 0) and ``mprgp``
    (the secant fixed point in the dual): their energies, largest damage, linear problems on Σ and iterations, and
    the relative energy difference and largest damage difference between them."""
    import ddsolve

    out = {}
    for method in ("schur", "mprgp"):
        scene = ddsolve.Scene.load("full-opening", [f'solver.method="{method}"', 'interface.law="bilinear"',
                                                    f"interface.strength={strength!r}",
                                                    f"interface.toughness={toughness!r}"])
        result = ddsolve.solve(scene, progress=lambda line: None)
        out[method] = {"energy": float(result.attrs["energy"]), "damage": np.asarray(result.multipliers["damage"]),
                       "bond_solves": int(result.attrs["bond_solves"]), "iterations": result.iterations,
                       "rounds": result.solves}
    schur, mprgp = out["schur"], out["mprgp"]
    out["energy_difference"] = abs(schur["energy"] / mprgp["energy"] - 1.0)
    out["damage_difference"] = float(np.abs(schur["damage"] - mprgp["damage"]).max())
    out["largest_damage"] = float(schur["damage"].max())
    return out


def griffith_load(opening: float, griffith: dict) -> float:
    """The Griffith run's load at ``opening`` on its branch (linear before initiation, then its grown steps)."""
    return float(np.interp(opening, griffith["displacement"], griffith["load"]))


def bond_run(size: float = SIZE, strength: float = STRENGTH, crack: float = CRACK, limit: float = 0.2,
             steps: int = 20) -> dict:
    """``ddsolve grow`` of the bilinear DCB to the opening ``limit``: its growth file's arrays, the wall time and
    the unknowns."""
    from ddsolve.solvers import bond_growth

    return timed_growth(bond_growth.grow, dcb_scene(True, size, strength=strength, crack=crack), limit, steps,
                        progress=lambda line: print(line, flush=True))


def griffith_run(size: float = SIZE, limit: float = 0.2, steps: int = 20) -> dict:
    """``ddsolve grow`` of the same DCB with the rigid bond and the Griffith toughness, as :func:`bond_run`."""
    from ddsolve.solvers import grow

    return timed_growth(grow.grow, dcb_scene(False, size), limit, steps, progress=lambda line: None)


def timed_growth(run, scene, limit: float, steps: int, progress) -> dict:
    """``run(scene, comm, limit, steps, progress=, output=)`` in one process: the growth file's arrays, the wall
    time (the mesh counted apart) and the unknowns."""
    from mpi4py import MPI

    from ddsolve.parallel import distribution
    from ddsolve.solvers import adapt, growth_files

    output = Path(tempfile.mkdtemp(prefix="cohesive-")) / "growth.h5"
    unknowns = adapt.unknowns(distribution.build_mesh(scene, MPI.COMM_SELF))
    started = time.perf_counter()
    run(scene, MPI.COMM_SELF, limit, steps, progress=progress, output=output)
    return {**growth_files.read(output), "seconds": time.perf_counter() - started, "unknowns": unknowns}


def dcb_growth(limit: float = 0.2, steps: int = 20, size: float = SIZE, strength: float = STRENGTH,
               griffith: dict | None = None) -> dict:
    """The bilinear DCB against Griffith on one mesh (module docstring; ``griffith`` a :func:`griffith_run` of the
    same ``size`` reaching at least ``limit`` if given): :func:`compared`."""
    bond = bond_run(size, strength, CRACK, limit, steps)
    griffith = griffith if griffith is not None else griffith_run(size, limit, steps)
    return compared(bond, griffith, CRACK, size)


def enf_griffith_run(size: float = ENF_SIZE, limit: float = ENF_LIMIT, steps: int = ENF_GRIFFITH_STEPS) -> dict:
    """``ddsolve grow`` of the ENF with the rigid bond and Griffith's toughness G_IIc, as :func:`bond_run`."""
    from ddsolve.solvers import grow

    return timed_growth(grow.grow, enf_scene(False, size), limit, steps, progress=lambda line: None)


def enf_growth(size: float = ENF_SIZE, strength: float = STRENGTH, griffith: dict | None = None,
               limit: float = ENF_LIMIT, steps: int = ENF_STEPS) -> dict:
    """The ENF with the bilinear law under Benzeggagh–Kenane against Griffith's growth (``griffith`` an
    :func:`enf_griffith_run` of the same ``size``, made if not given): :func:`compared`."""
    from ddsolve.solvers import bond_growth

    bond = timed_growth(bond_growth.grow, enf_scene(True, size, strength), limit, steps,
                        progress=lambda line: print(line, flush=True))
    griffith = griffith if griffith is not None else enf_griffith_run(size, limit)
    return compared(bond, griffith, ENF_CRACK, size)


def compared(bond: dict, griffith: dict, crack: float, size: float) -> dict:
    """A bond run's growth file (``bond``) against Griffith's of the same structure and mesh (``griffith``), its
    initial crack (0, ``crack``): per bond step the opening, load, crack tip, process zone and the Griffith load; the
    largest deviations before damage and once the crack grows."""
    tips = bond["cracks"][:, 0, 1]
    damaged = bond["damage"].max(axis=1) > 0.0
    grown = tips > crack + 1e-9
    expected = np.array([griffith_load(d, griffith) for d in bond["displacement"]])
    deviation = np.abs(bond["load"] / np.where(expected > 0, expected, np.nan) - 1.0)
    spacing = size / 2.0  # P2: the Σ nodes' spacing
    return {"opening": bond["displacement"].tolist(), "load": bond["load"].tolist(), "griffith": expected.tolist(),
            "tip": tips.tolist(), "process_zone": bond["process_zone"].tolist(), "solves": bond["solves"].tolist(),
            "before_damage": float(np.nanmax(deviation[~damaged])) if np.isfinite(deviation[~damaged]).any() else np.nan,
            "grown": float(np.nanmax(deviation[grown], initial=np.nan)),
            "elements_per_zone": float(np.nanmedian(bond["process_zone"][grown]) / spacing) if grown.any() else np.nan,
            "steps": len(tips) - 1, "seconds": bond["seconds"], "unknowns": bond["unknowns"],
            "irreversible": bool(np.all(np.diff(bond["damage"], axis=0) >= 0.0)),
            "newton": bond["bond_solves"].tolist()}


def main() -> None:
    for row in stiff_limit():
        print(f"elastic k = {row['stiffness']:.0e} ({row['method']}): energy {row['energy']:.12e}, relative "
              f"difference from the rigid bond {row['difference']:.3e}, schur against mprgp {row['methods_differ']:.1e}")
    both = bilinear_methods()
    print(f"bilinear on full-opening: largest damage {both['largest_damage']:.4f}; schur {both['schur']['bond_solves']} "
          f"linear problems on Σ, {both['schur']['rounds']} rounds; mprgp {both['mprgp']['bond_solves']}, "
          f"{both['mprgp']['rounds']} rounds; energies differ by {both['energy_difference']:.1e}, damage by "
          f"{both['damage_difference']:.1e}")
    record = dcb_growth()
    for opening, load, griffith, tip, zone in zip(record["opening"], record["load"], record["griffith"], record["tip"],
                                                   record["process_zone"]):
        print(f"DCB opening {opening:.5f}: load {load:.6e} (Griffith {griffith:.6e}), tip {tip:.4f}, process zone "
              f"{zone:.4f}")
    print(f"DCB: largest deviation before damage {record['before_damage']:.3%}, once the crack grows "
          f"{record['grown']:.3%}; {record['elements_per_zone']:.1f} Σ nodes per process zone; {record['steps']} steps "
          f"in {record['seconds']:.0f} s")


if __name__ == "__main__":
    main()
