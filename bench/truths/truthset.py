"""The hidden truths of the independent families and the answer each expects.

Each family implements every *ingredient* in its own physics (``pnp_fd`` and ``circuit_lab``
write them differently); this table only says which ingredients a truth switches on and which
catalog ids the verdict should name.  Catalog ids appear here only as expected answers.

=================  =======  ==========================================  ==========================
truth              kind     ingredients (family physics)                expected (acceptable)
=================  =======  ==========================================  ==========================
none               none     —                                           — (nothing named)
electrode          catalog  electrode sheet resistance along the strip  electrode_resistance
rough              catalog  rough / porous electrode, constant phase    fractional_coupling
                                                                        (fractional_charge)
solvent            catalog  solvent back-diffusion (back-relaxation)    solvent_diffusion
modulus            catalog  frequency-dependent modulus                 viscoelastic
saturation         catalog  large-signal double-layer saturation        nonlinear_charge
humidity           catalog  RH-dependent stiffness and coupling         humidity
creep              outside  creeping output                             —
lowpass2           outside  2nd-order sensor low-pass 10–20 Hz          —
drift              outside  sensor warm-up drift, different per record  —
play               outside  backlash between strip and sensor           —
deadzone           outside  dead zone of the drive                      —
eigen_moment       outside  bimorph-like eigen-moment instead of the    —
                            face tractions' distributed couple
delay              outside  deflection logged 4–15 ms late (dead time)  —
ac_coupled         outside  sensor AC-coupled (0.01–0.04 Hz high-pass)   —
hum                outside  50 Hz mains pickup of 2–4 µm on the sensor   —
bow                outside  sensor's bowed characteristic, ±3–8 %       —
clipped            outside  sensor's range cut at 75–90 % of the stroke  —
twin_contact       twin     lumped contact resistance at the clamp      — (electrode_resistance)
twin_relax         twin     partial back-relaxation                     — (solvent_diffusion)
twin_zener         twin     one-relaxation (Zener) polymer, loss peak   — (viscoelastic)
pair_rough_solvent pair     rough + solvent                             both
pair_lowpass_sat   pair     lowpass2 + saturation                       nonlinear_charge
pair_elec_solvent  pair     electrode + solvent                         both
pair_modulus_rh    pair     modulus + humidity                          both
pair_elec_modulus  pair     electrode + modulus                         both
pair_sat_solvent   pair     saturation + solvent                        both
route_creep_rh     route    creep + an RH law the user's model lacks    (humidity); the default
                            (its humidity maps, if any, are kept)       route's error ≤ 3× true
=================  =======  ==========================================  ==========================

A near twin's relative is *acceptable* (not wrong, not required): its physics is the same
phenomenon in a form the catalog effect's parametrisation does not hold.  Both families write a
rough electrode as a constant-phase double layer (the charge is fractional, behind the electrodes'
resistance), which is ``fractional_charge``; the diagnosis tries that law only on request, so the
default route's answer is the thesis's fractional load constant ``fractional_coupling`` (the same
deflection on equipotential electrodes) and ``fractional_charge`` is acceptable.
"""
from __future__ import annotations

from .case import Truth

#: ingredient → the catalog effect it is an analogue of (None: outside the catalog)
CATALOG_OF = {"electrode": "electrode_resistance", "rough": "fractional_coupling", "solvent": "solvent_diffusion",
              "modulus": "viscoelastic", "saturation": "nonlinear_charge", "humidity": "humidity"}
#: ingredient → a catalog relative: the same phenomenon in another form (acceptable, not required)
RELATIVE_OF = {"rough": "fractional_charge"}
SLOW = ("solvent", "rough")


def _catalog(name: str) -> Truth:
    relative = (RELATIVE_OF[name],) if name in RELATIVE_OF else ()
    return Truth(name, "catalog", (CATALOG_OF[name],), relative, (name,), slow=name in SLOW)


def _pair(name: str, a: str, b: str) -> Truth:
    exp = tuple(CATALOG_OF[x] for x in (a, b) if x in CATALOG_OF)
    return Truth(name, "pair", exp, tuple(RELATIVE_OF[x] for x in (a, b) if x in RELATIVE_OF), (a, b),
                 slow=any(x in SLOW for x in (a, b)))


TRUTHS: dict[str, Truth] = {t.name: t for t in (
    Truth("none", "none"),
    *(_catalog(n) for n in ("electrode", "rough", "solvent", "modulus", "saturation", "humidity")),
    *(Truth(n, "outside", (), (), (n,)) for n in ("creep", "lowpass2", "drift", "play", "deadzone", "eigen_moment",
                                                  "delay", "ac_coupled", "hum", "bow", "clipped")),
    Truth("twin_contact", "twin", (), ("electrode_resistance",), ("contact",)),
    Truth("twin_relax", "twin", (), ("solvent_diffusion",), ("partial_relax",), slow=True),
    Truth("twin_zener", "twin", (), ("viscoelastic",), ("zener",)),
    _pair("pair_rough_solvent", "rough", "solvent"),
    _pair("pair_lowpass_sat", "lowpass2", "saturation"),
    _pair("pair_elec_solvent", "electrode", "solvent"),
    _pair("pair_modulus_rh", "modulus", "humidity"),
    _pair("pair_elec_modulus", "electrode", "modulus"),
    _pair("pair_sat_solvent", "saturation", "solvent"),
    Truth("route_creep_rh", "route", (), ("humidity",), ("creep", "rh_law"), slow=True),
)}
