"""The paper's §2 model: a rigid box on a rigid ground, pulled by an elastic rope from a sprung boom tip.

One mechanism serves every phase of the motion (rest, sliding, tipping about an edge or a corner, flight):
constrained Newton-Euler dynamics (2.10)-(2.11) for the current set of active contacts. Each bottom corner
D, E, F, H is in one of three contact modes, carried in `Phase.contact`:

- `FREE`: no ground force;
- `SLIDE`: on the ground (Z_i = 0 enforced), normal force N_i >= 0 and Coulomb friction -μ N_i t̂_i
  opposite to the sliding direction t̂_i (eq. 2.18), t̂_i = v_i,h / |v_i,h| blended with the phase's
  `slip_hint` below `slip_velocity` so that sliding can start from rest;
- `STICK`: the corner does not move (all three velocity components held at zero), ground force free.

The unknown contact forces λ (3 per corner) solve the small linear system "constrained corner accelerations
vanish" (with Baumgarte stabilisation of the drift); redundant contacts (four coplanar corners, or two
sticking corners sharing an edge) make it singular: four corners on the ground carry the paper's linear
distribution (2.3) (which at rest is the minimum-norm solution), and what remains indeterminate takes
the minimum norm (SVD pseudo-inverse). When the body is at rest on all
four corners (`Phase.rest`) it is held fixed and only the boom tip moves; the phase lasts while the load
can rest: N > 0, R inside the rectangle, and the exact corner friction utilisation ρ* <= 1 (`statics`).

A phase ends at the first zero of one of its guards (all positive while the phase is valid):
a contact's normal force reaching 0 (lift-off of that corner), a free corner reaching the ground
(touch-down or impact), a sticking corner's friction reaching μN_i (slip), a sliding corner's velocity
along its sliding direction reaching 0 (stop or turn), and for rest: R leaving the rectangle (tip) or
ρ* reaching 1 (slip). The choice of the next phase, impacts and the phase loop live in
`numerics.rigid.solve`.

The state is `elastic.State` (with an empty friction state, shape (4, 0)); the rope (2.14) and the boom
(2.13) are the force laws of `forces`. With `inextensible=True` the rope is instead the constraint (2.15)
|AB| = l(t) (taut or slack by `Phase.rope`): a taut rope's tension joins the contact forces as an unknown,
and the boom tip's acceleration joins the constrained accelerations. All functions are pure JAX.
"""

# The definitions live in `contact` (contact modes, phases, settings, loads, contact matrices) and
# `dynamics` (the dynamics of a phase, its guards, impulses, energies and outputs; it imports
# `contact`); this module re-exports both so that `physics.rigid` stays the one name to use.
from .contact import (  # noqa: I001
    FREE as FREE,
    SLIDE as SLIDE,
    STICK as STICK,
    ROPE_ELASTIC as ROPE_ELASTIC,
    ROPE_TAUT as ROPE_TAUT,
    ROPE_SLACK as ROPE_SLACK,
    MODE_NAMES as MODE_NAMES,
    CORNERS as CORNERS,
    ROPE_NAMES as ROPE_NAMES,
    N_GUARDS as N_GUARDS,
    GUARD_NAMES as GUARD_NAMES,
    Phase as Phase,
    make_phase as make_phase,
    Settings as Settings,
    Scales as Scales,
    scales as scales,
    initial_state as initial_state,
    Loads as Loads,
    loads as loads,
    inextensible_loads as inextensible_loads,
    with_tension as with_tension,
    rope_accel_target as rope_accel_target,
    tip_free_accel as tip_free_accel,
    rest_rope_tension as rest_rope_tension,
    mass_inverse as mass_inverse,
    slip_directions as slip_directions,
    maps as maps,
    block_diag as block_diag,
    solve_contact_system as solve_contact_system,
    solve_rope_contact_system as solve_rope_contact_system,
    ContactMatrices as ContactMatrices,
    contact_matrices as contact_matrices,
)
from .dynamics import (  # noqa: E402, I001
    Contact as Contact,
    contact_dynamics as contact_dynamics,
    contact_elastic as contact_elastic,
    contact_from_multipliers as contact_from_multipliers,
    contact_problem as contact_problem,
    contact_rope as contact_rope,
    energy as energy,
    event_condition as event_condition,
    impulse_response as impulse_response,
    kinetic_energy as kinetic_energy,
    motion_contact_free as motion_contact_free,
    motion_contact_rope as motion_contact_rope,
    motion_contact_taut as motion_contact_taut,
    motion_guards as motion_guards,
    motion_guards_rope as motion_guards_rope,
    Output as Output,
    output as output,
    raw_guards as raw_guards,
    rest_conditions as rest_conditions,
    rest_contact as rest_contact,
    rest_contact_rope as rest_contact_rope,
    rest_friction as rest_friction,
    rest_guards as rest_guards,
    rest_guards_rope as rest_guards_rope,
    rest_loads as rest_loads,
    rope_guards as rope_guards,
    rope_impulse_response as rope_impulse_response,
    unpack as unpack,
    vector_field as vector_field,
)
from .model import AbstractRope as AbstractRope  # noqa: E402
from .model import ElasticRope as ElasticRope  # noqa: E402
from .model import InextensibleRope as InextensibleRope  # noqa: E402
from .model import RigidGround as RigidGround  # noqa: E402
