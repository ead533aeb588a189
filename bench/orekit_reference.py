"""Orekit's propagation of the force-model benchmark's cases (run by bench_force_model.py).

Runs in a separate virtual environment with ``orekit-jpype``, ``jplephem`` and ``de421``
(never a dependency of ssa_fusion; bench_force_model.py says how to create it)::

    OREKIT_VENV/bin/python bench/orekit_reference.py JOB.json OUT.json

JOB.json (written by bench_force_model.py): ``data_dir`` (a directory Orekit reads: the
IERS ``finals2000A.all`` and leap seconds the product uses, the EGM96 ``.gfc`` file),
``gravity_file``, ``epoch`` (UTC) with ``tdb_minus_tt`` s there and its rate ``tdb_rate``,
``earth_share``, ``gm_sun``/``gm_moon`` m^3/s^2 and
``cases``: each an epoch (UTC ISO), a GCRF state (m, m/s), the forces and the output
offsets (s). Orekit propagates each with its own numerical propagator (adaptive
Dormand-Prince 8(5,3), the case's tolerance and longest step, Cartesian),
HolmesFeatherstone on its ITRF (IERS 2010, EOP without tidal corrections), its
ThirdBodyAttraction, SolarRadiationPressure (conical shadow of a spherical Earth, with its
own eclipse detection) and DragForce in a SimpleExponentialAtmosphere. The Sun and the Moon
are DE421 evaluated by jplephem here (the ``de421`` package Orekit cannot read), given to
Orekit as ExtendedPositionProviders. Writes the positions (m, GCRF) at the offsets to OUT.json.
"""

from __future__ import annotations

import json
import sys

import de421
import orekit_jpype as orekit
from jplephem.ephem import Ephemeris

orekit.initVM()

from jpype import JClass, JImplements, JOverride  # noqa: E402
from orekit_jpype.pyhelpers import setup_orekit_data  # noqa: E402

EPH = Ephemeris(de421)


CLASSES = (
    "org.hipparchus.geometry.euclidean.threed.Vector3D",
    "org.hipparchus.ode.nonstiff.DormandPrince853Integrator",
    "org.orekit.bodies.OneAxisEllipsoid",
    "org.orekit.forces.drag.DragForce", "org.orekit.forces.drag.IsotropicDrag",
    "org.orekit.forces.gravity.HolmesFeatherstoneAttractionModel",
    "org.orekit.forces.gravity.ThirdBodyAttraction",
    "org.orekit.forces.gravity.potential.GravityFieldFactory",
    "org.orekit.forces.gravity.potential.ICGEMFormatReader",
    "org.orekit.forces.radiation.IsotropicRadiationSingleCoefficient",
    "org.orekit.forces.radiation.SolarRadiationPressure",
    "org.orekit.frames.FramesFactory",
    "org.orekit.models.earth.atmosphere.SimpleExponentialAtmosphere",
    "org.orekit.orbits.CartesianOrbit", "org.orekit.orbits.OrbitType",
    "org.orekit.propagation.SpacecraftState",
    "org.orekit.propagation.numerical.NumericalPropagator",
    "org.orekit.time.AbsoluteDate", "org.orekit.time.TimeScalesFactory",
    "org.orekit.utils.IERSConventions", "org.orekit.utils.PVCoordinates",
    "org.orekit.utils.TimeStampedPVCoordinates",
)


def _classes() -> dict:
    return {name.rsplit(".", 1)[1]: JClass(name) for name in CLASSES}


def main(job_path: str, out_path: str) -> None:
    with open(job_path) as f:
        job = json.load(f)
    setup_orekit_data(filenames=job["data_dir"], from_pip_library=False)
    k = _classes()
    k["GravityFieldFactory"].addPotentialCoefficientsReader(
        k["ICGEMFormatReader"](job["gravity_file"], False))
    gcrf = k["FramesFactory"].getGCRF()
    itrf = k["FramesFactory"].getITRF(k["IERSConventions"].IERS_2010, True)
    tt = k["TimeScalesFactory"].getTT()
    j2000 = k["AbsoluteDate"].J2000_EPOCH
    origin = k["AbsoluteDate"](job["epoch"], k["TimeScalesFactory"].getUTC()).durationFrom(j2000)
    V = k["Vector3D"]

    def body_gcrf(date: object, which: str) -> list[float]:
        tt_s = date.durationFrom(j2000)
        d = (tt_s + job["tdb_minus_tt"] + job["tdb_rate"] * (tt_s - origin)) / 86400.0
        moon = EPH.position("moon", 2451545.0, d).ravel()
        if which == "moon":
            return [1e3 * float(v) for v in moon]
        sun = (EPH.position("sun", 2451545.0, d)
               - EPH.position("earthmoon", 2451545.0, d)).ravel()
        return [1e3 * float(s + job["earth_share"] * m) for s, m in zip(sun, moon, strict=True)]

    @JImplements("org.orekit.utils.ExtendedPositionProvider")
    class Body:
        def __init__(self, which: str) -> None:
            self.which = which

        @JOverride
        def getPosition(self, date: object, frame: object) -> object:
            p = V(*body_gcrf(date, self.which))
            return gcrf.getTransformTo(frame, date).transformPosition(p)

        @JOverride
        def getPVCoordinates(self, date: object, frame: object) -> object:
            h = 1.0
            p0 = V(*body_gcrf(date.shiftedBy(-h), self.which))
            p1 = V(*body_gcrf(date.shiftedBy(h), self.which))
            pv = k["TimeStampedPVCoordinates"](
                date, V(*body_gcrf(date, self.which)),
                V(0.5 / h, p1.subtract(p0)))
            return gcrf.getTransformTo(frame, date).transformPVCoordinates(pv)

    out = {}
    for case in job["cases"]:
        out[case["name"]] = _propagate(case, k, gcrf, itrf, tt, Body, job)
    with open(out_path, "w") as f:
        json.dump(out, f)


def _forces(case: dict, k: dict, itrf: object, Body: type, job: dict) -> tuple[list, float]:
    f = case["forces"]
    provider = k["GravityFieldFactory"].getNormalizedProvider(f["degree"], f["order"])
    mu = provider.getMu()
    forces = []
    if f["degree"] >= 2:
        forces.append(k["HolmesFeatherstoneAttractionModel"](itrf, provider))
    if f["sun"]:
        forces.append(k["ThirdBodyAttraction"](Body("sun"), "Sun", job["gm_sun"]))
    if f["moon"]:
        forces.append(k["ThirdBodyAttraction"](Body("moon"), "Moon", job["gm_moon"]))
    sphere = k["OneAxisEllipsoid"](job["earth_radius"], 0.0, itrf)
    mass = case["mass"]
    if f["srp"]:
        sc = k["IsotropicRadiationSingleCoefficient"](f["area_to_mass"] * mass, f["cr"])
        forces.append(k["SolarRadiationPressure"](job["au"], job["solar_pressure"],
                                                  Body("sun"), sphere, sc))
    if f["drag"]:
        atm = k["SimpleExponentialAtmosphere"](sphere, f["rho0"], f["h0"], f["scale_height"])
        cd = 2.0
        forces.append(k["DragForce"](atm, k["IsotropicDrag"](mass / (cd * f["bc"]), cd)))
    return forces, mu


def _propagate(case: dict, k: dict, gcrf: object, itrf: object, tt: object, Body: type,
               job: dict) -> list[list[float]]:
    forces, mu = _forces(case, k, itrf, Body, job)
    date = k["AbsoluteDate"](case["epoch"], k["TimeScalesFactory"].getUTC())
    x = case["x0"]
    pv = k["PVCoordinates"](k["Vector3D"](*x[:3]), k["Vector3D"](*x[3:]))
    orbit = k["CartesianOrbit"](pv, gcrf, date, mu)
    tol = k["NumericalPropagator"].tolerances(case.get("tolerance", 1e-4), orbit,
                                              k["OrbitType"].CARTESIAN)
    integ = k["DormandPrince853Integrator"](1e-3, case["max_step"], tol[0], tol[1])
    prop = k["NumericalPropagator"](integ)
    prop.setOrbitType(k["OrbitType"].CARTESIAN)
    prop.setInitialState(k["SpacecraftState"](orbit, case["mass"]))
    for fm in forces:
        prop.addForceModel(fm)
    out = []
    for dt in case["offsets"]:
        p = prop.propagate(date.shiftedBy(float(dt))).getPVCoordinates(gcrf).getPosition()
        out.append([p.getX(), p.getY(), p.getZ()])
    return out


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit("usage: orekit_reference.py JOB.json OUT.json")
    main(sys.argv[1], sys.argv[2])
