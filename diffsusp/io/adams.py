"""Adams datasets (.adm): the parser (`adams_parse`), the interpreter into a `Mechanism`
(`adams_plan`) and the writer (`adams_write`), re-exported here with `read_adm`. The property
files (TeimOrbit, A/Car .lcf and .bus) are in `adams_property` (re-exported here), the shared
text helpers and unit tables in `adams_common`.

spec: stiffness §4.1 (the .adm of Annex F, `model_exemple11`), §4.2 (.lcf, Annex H), §4.3 (A/Car
bushing splines, Annex I), §4.4, §6 item 10, §7 R9. Reading never executes anything from a file:
statements are tokenised by regular expressions and function expressions are parsed by the small
grammar of `diffsusp.io.expr`.

**.adm subset read** (statement → diffsusp):

- first line: the title (Adams's rule; a first line that is itself a statement is read as one);
- ``!`` comments; ``! adams_view_name='x'`` names the next statement (parts, markers, elements
  take these names; unnamed ones are called ``MARKER_7``, ``BUSHING_1``, ...); a commented-out
  statement (``!JOINT/1, ...``) is inactive and listed in `AdmModel.inactive`; lines starting
  with ``,`` continue the statement; ``\\`` ends a function expression; ``END`` ends the dataset;
- ``UNITS/`` FORCE, LENGTH (MASS and TIME recorded), or SYSTEM; values are converted to mm, N,
  N·mm, rad (no UNITS statement: mm and N assumed);
- ``PART/`` GROUND; QG/REULER (or ZG/XG) place the part frame at design; MASS, CM, IP, initial
  velocities are ignored (statics);
- ``MARKER/`` PART, QP, REULER (or ZP/XP) in the part frame; a ``D`` suffix means degrees;
  FLOATING markers get no pose (they only carry GFORCE/VFORCE/VTORQUE reactions);
- ``JOINT/`` SPHERICAL, REVOLUTE, CYLINDRICAL, TRANSLATIONAL, UNIVERSAL, FIXED;
  ``JPRIM/`` INLINE, INPLANE, PERPENDICULAR, ATPOINT (= spherical rows);
- ``BUSHING/`` I, J, K, KT, FORCE, TORQUE (C, CT are damping: ignored in statics) — Adams
  convention, the one of `diffsusp.model.Bushings`;
- ``SPRINGDAMPER/`` TRANSLATIONAL: tension K·(ℓ − LENGTH) − FORCE, i.e. a linear spring of free
  length LENGTH + FORCE/K (when that is ≤ 0 or K = 0, the same law as a 2-point table);
  ROTATIONAL: a bushing with only KT about z (offset ANGLE, preload TORQUE);
- ``SFORCE/`` with a FUNCTION of the grammar: ACTIONONLY → a load point on I in J's axes
  (TRANSLATIONAL: force along z_J, ROTATIONAL: torque about z_J); two-body TRANSLATIONAL → a
  constant tension −f along I–J (Adams: positive repels); two-body ROTATIONAL → a zero-stiffness
  bushing with torque preload f about z_J; two-body functions are evaluated at `time`;
  two-body TRANSLATIONAL ``k * MAX(0, L - DM(i, j))`` (``-(k * MAX(0, DM(i, j) - L))``), each
  optionally ``+ c * MAX(…)**3``, on its own I, J → a bump (rebound) stop of length L, rate k,
  cubic c (`stop_of_function`; what `write_adm` writes for stops);
- ``GFORCE/``, ``VFORCE/``, ``VTORQUE/`` with JFLOAT a floating marker on the ground: a load
  point on I, components in RM's axes; their FX…TZ expressions are evaluated by
  `AdmModel.loads` at the times asked for (a reaction on a moving part is not supported:
  skipped);
- ``MOTION/`` I, J on the ground, X/Y/Z (or JOINT= a translational joint, TRANSLATION): a motion
  driver on I along J's axis, values from `AdmModel.loads`;
- ``GCON/`` FUNCTION = DM(i, j) − L: a distance joint (massless link) between markers i and j;
- ``SPLINE/`` X, Y, LINEAR_EXTRAPOLATE: stored in `AdmModel.splines`; A/Car bushing splines
  (six splines named ``<bushing>_{fx,fy,fz,tx,ty,tz}_spline``) are grouped by
  `AdmModel.spline_bushings` and their linear stiffness read by `spline_stiffness` (Y = −K·X,
  §4.3). The GFORCE/FIELD that uses them in A/Car datasets is not printed in the thesis, so they
  are not attached to a bushing.

Statements without effect on a static solution (GRAPHICS, OUTPUT, RESULTS, REQUEST, ...) are
listed in `AdmModel.ignored`. Every other statement (ACCGRAV, FIELD, BEAM, CONTACT, an
unsupported joint type, a function outside the grammar, ...) is reported by keyword, id, name and
line in `AdmModel.skipped` and in a `ModelWarning`, never silently dropped.

Ground markers without an ``adams_view_name`` that serve only as reference frames (RM, the J of
an action-only SFORCE or of a MOTION) are not added to the mechanism: their axes never move, so
loads are given in global components and motions along their global axis.
"""

from ..model import Mechanism
from .adams_parse import (  # noqa: F401  (re-exported: the parser's API)
    NO_STATIC_EFFECT,
    SUPPORTED,
    AdmArgument,
    AdmModel,
    AdmSpline,
    AdmStatement,
    AdmValue,
    SkippedStatement,
    spline_stiffness,
    stop_of_function,
)
from .adams_plan import parse_adm
from .adams_property import (  # noqa: F401  (re-exported: the property files' API)
    BushingProperty,
    LoadCaseTable,
    TeimBlock,
    TeimTable,
    parse_teimorbit,
    read_bushing_property,
    read_lcf,
    write_bushing_property,
    write_lcf,
)
from .adams_write import stop_function, write_adm  # noqa: F401  (re-exported)


def read_adm(path, *, time: float = 0.0, check: bool = True) -> Mechanism:
    """Read an Adams dataset (.adm) into a `Mechanism` (see the module docstring for the
    subset). Two-body SFORCE functions are evaluated at `time` (s); the external loads and
    motions of the file are given by `parse_adm(path).loads(mech, times)`. `check`: validate
    the model (free modes, joints assembled), as `MechanismBuilder.build`.

    spec: stiffness §4.1 (Annex F), §6 item 10.
    """
    return parse_adm(path).build(time, check=check)
