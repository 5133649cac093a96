"""The DEM solver: a step only orders launcher calls; host checks happen once per ``run`` chunk."""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np
import warp as wp

from warpdem.errors import InputError, SimulationError
from warpdem.kernels import neighbors as _nb
from warpdem.kernels import step as _st
from warpdem.kernels.features import StepFeatures

from .types import ContactLaw, Contacts, Control, Model, Overflow, State, host

CLUMP_CONTACT_MASSES = ("shared", "body")
"""The values of SolverOptions.clump_contact_mass (also a stage's warpdem:run:clumpContactMass)."""


@dataclass(frozen=True)
class SolverOptions:
    """Solver settings, validated at construction.

    Attributes:
        dt: time step [s]; None chooses ``dt_fraction`` of the Rayleigh time.
        dt_fraction: fraction of the Rayleigh time used for the automatic step, in (0, 1] (EDEM's 20 %).
        skin: Verlet skin [m]; None uses ``skin_fraction`` x the smallest radius.
        skin_fraction: the automatic skin as a fraction of the smallest radius, > 0 (default 0.4). The lists
            are rebuilt whenever any sphere of the launch has moved half the skin, so a fast stream (pellets
            leaving a funnel) rebuilds every few steps; a larger skin rebuilds less often but lists more
            candidates per sphere.
        neighbor_capacity: candidate slots per sphere; None derives it from the radius ratio.
        mesh_capacity: candidate triangle slots per sphere.
        velocity_limit: a sphere faster than this [m/s] stops the run as a blow-up.
        impact_speed_min: a sphere's first touch of a wall face counts as an impact (``State.face_impact_*``)
            when its normal approach speed is at least this [m/s]; it keeps resting contacts that chatter
            out of the impact statistics.
        clump_contact_mass: the mass a clump's sub-sphere contact damps: "shared" (default) divides the
            clump's mass by its number of sub-sphere contacts with the same partner body at the previous
            step, so a flat face whose n spheres touch at once rebounds with the pair's restitution and the
            explicit step stays stable;
            "body" gives every sub-contact the whole clump mass (EDEM's convention): such a face is then
            about sqrt(n) times overdamped (a 3 x 3 raft dropped flat rebounds at 0.02 for e = 0.45) and,
            with tens of sub-contacts, the damping outgrows the time step and the clump spins up.
        dt_margin: the step may use at most this fraction of the stiffest contact's stable step, in (0, 1].
            Every step finds, without a host read, the largest sum over one sphere's contacts of each contact's
            squared stable-step frequency (its law's current tangent stiffness and dashpot, normal on m* and
            tangential on the tangential mode's 2/7 m*: kernels/law_hertz_mindlin.py ``stable_rate``), a
            Gershgorin bound on the fastest mode, Omega^2; leapfrog is stable while the margin dt Omega / 2 < 1.
            The Rayleigh time covers an impact, not a Hertz contact compressed deep (S grows as sqrt(overlap)),
            EEPA's unloading branch or a strong dashpot. :attr:`Solver.step_margin` reports each ``run``'s margin.
        dt_levels: how many times :meth:`Solver.advance` may halve the step when a ``run`` exceeded
            ``dt_margin`` (and double it back, never above the Rayleigh or given step, when the margin has
            fallen well below), so dt is that step / 2^k with 0 <= k <= dt_levels; 0 keeps dt fixed and only
            reports. The choice is made between runs from what the last run met, so a run stays deterministic
            and bit-reproducible from its inputs; a batch steps at the dt its stiffest world needs.
    """

    dt: float | None = None
    dt_fraction: float = 0.2
    skin: float | None = None
    skin_fraction: float = 0.4
    neighbor_capacity: int | None = None
    mesh_capacity: int = 16
    velocity_limit: float = 500.0
    impact_speed_min: float = 0.05
    clump_contact_mass: str = "shared"
    dt_margin: float = 0.5
    dt_levels: int = 6

    def __post_init__(self):
        def bad(name, value, allowed):
            raise InputError(f"SolverOptions: {name} = {value!r} is not allowed; expected {allowed}")

        if self.dt is not None and not (math.isfinite(self.dt) and self.dt > 0):
            bad("dt", self.dt, "a time step > 0 s or None (automatic)")
        if not (math.isfinite(self.dt_fraction) and 0 < self.dt_fraction <= 1):
            bad("dt_fraction", self.dt_fraction, "a fraction of the Rayleigh time in (0, 1]")
        if self.skin is not None and not (math.isfinite(self.skin) and self.skin > 0):
            bad("skin", self.skin, "a skin > 0 m or None (automatic)")
        if not (math.isfinite(self.skin_fraction) and self.skin_fraction > 0):
            bad("skin_fraction", self.skin_fraction, "a fraction of the smallest radius > 0")
        if self.neighbor_capacity is not None and not (int(self.neighbor_capacity) >= 1):
            bad("neighbor_capacity", self.neighbor_capacity, "an integer >= 1 or None (automatic)")
        if int(self.mesh_capacity) < 1:
            bad("mesh_capacity", self.mesh_capacity, "an integer >= 1")
        if not (self.velocity_limit > 0):
            bad("velocity_limit", self.velocity_limit, "a speed > 0 m/s")
        if not (math.isfinite(self.impact_speed_min) and self.impact_speed_min >= 0):
            bad("impact_speed_min", self.impact_speed_min, "a speed >= 0 m/s")
        if self.clump_contact_mass not in CLUMP_CONTACT_MASSES:
            bad("clump_contact_mass", self.clump_contact_mass, '"shared" or "body"')
        if not (math.isfinite(self.dt_margin) and 0 < self.dt_margin <= 1):
            bad("dt_margin", self.dt_margin, "a fraction of the stable step in (0, 1]")
        if not (
            isinstance(self.dt_levels, (int, float))
            and float(self.dt_levels).is_integer()
            and 0 <= self.dt_levels <= 20
        ):
            bad("dt_levels", self.dt_levels, "an integer from 0 (fixed step) to 20")


DT_RAISE = 2.0 / 3.0
"""Solver.advance doubles the step only when the doubled margin stays below this fraction of dt_margin, so the
step does not flip between two levels at every output."""

# steps in one replayed CUDA graph: long enough to hide the launch cost, short enough for a remainder
# stepped eagerly to stay cheap
CUDA_GRAPH_STEPS = 32


ROW_BYTES_MAX = 2**31 - 1
"""Warp keeps an array's strides as int32: a slot-major list array (slots, sphere_count) whose row of one slot
per sphere passes 2 GiB would be addressed wrongly on the GPU (a memory fault, or silently wrong slots)."""


def check_row_bytes(sphere_count: int, dtype) -> None:
    """Refuse a list array whose row (one slot per sphere) is too long for Warp's int32 strides."""
    size = wp.types.type_size_in_bytes(dtype)
    if sphere_count * size > ROW_BYTES_MAX:
        raise InputError(
            f"Solver.contacts: sphere_count = {sphere_count:,} is not allowed with {size}-byte "
            f"{getattr(dtype, '__name__', dtype)} list slots; expected at most {ROW_BYTES_MAX // size:,} spheres "
            "in one model (Warp addresses a row of one slot per sphere with int32 strides): split the launch "
            "into fewer worlds"
        )


def drive(gen):
    """Run the generator ``gen`` (:meth:`Solver.run_iter`, :meth:`Solver.advance_iter`,
    ``runner.run_scene_iter``) to its end; returns its return value."""
    while True:
        try:
            next(gen)
        except StopIteration as stop:
            return stop.value


class Solver:
    """Hertz-Mindlin DEM on spheres, planes and static triangle meshes (see kernels/step.py).

    Typical use::

        solver = Solver(model, SolverOptions())
        state = model.state()
        contacts = solver.contacts()
        state = solver.run(state, contacts, steps=1000)
    """

    def __init__(self, model: Model, options: SolverOptions | None = None):
        self.model = model
        self.options = options or SolverOptions()
        # EEPA unloads along k2 = k1 / (1 - lambda_p): the stiffest branch sets the stable step
        pairs = host(model.pair_params)
        lam = float(np.max(pairs["lambda_p"] * (pairs["law"] == int(ContactLaw.EEPA))))
        auto = self.options.dt_fraction * model.rayleigh_time * math.sqrt(1.0 - lam)
        if self.options.dt is None:
            self.dt = auto
        else:
            self.dt = float(self.options.dt)
            if self.dt > auto:
                warnings.warn(
                    f"time step {self.dt:.3g} s exceeds {self.options.dt_fraction:.0%} of the Rayleigh time "
                    f"({model.rayleigh_time:.3g} s): contacts may be under-resolved",
                    stacklevel=2,
                )
        self.dt_base = self.dt
        """The Rayleigh or given step [s]: :meth:`advance` steps at ``dt_base / 2**dt_level``."""
        self.dt_level = 0
        self.step_margin: float | None = None
        """dt Omega / 2 over the last ``run`` (None before the first): below 1 leapfrog is stable (SolverOptions.
        dt_margin)."""
        self.step_margin_max = 0.0
        """The largest ``step_margin`` of this solver's runs."""
        self._kick_next: float | None = None
        self.skin = (
            self.options.skin if self.options.skin is not None else self.options.skin_fraction * model.radius_min
        )
        self.features = StepFeatures.of(model, share_mass=self.options.clump_contact_mass == "shared")
        """What the model uses: the step and rebuild kernels are compiled for it (kernels/features.py)."""
        self._buffers = _st.StepBuffers.zeros(model)
        self.control = model.control()
        """The wall motion used when run or step get no Control."""
        self._spare: State | None = None
        # host copy of the rebuild flag, read between captured steps on CUDA (pinned: an async 4-byte copy)
        self._is_cuda = wp.get_device(model.device).is_cuda
        self._flag_host = wp.empty(1, dtype=int, device="cpu", pinned=self._is_cuda)
        # captured graphs by (twin states, contacts, control, kind), with those objects kept alive: an id is
        # never reused while its graphs are kept; emptied at a change of step
        self._graph: dict = {}
        self.cuda_graph_steps = CUDA_GRAPH_STEPS
        """Steps per replayed CUDA graph (even); 0 reads the rebuild flag on the host every step instead."""

    # contacts -------------------------------------------------------------------------------
    def default_neighbor_capacity(self) -> int:
        """Slots for all partners within r_i + r_j + skin: a shell-packing estimate, at least 16."""
        m = self.model
        ratio = (m.radius_max + m.radius_min + self.skin) / m.radius_min
        # spheres of the smallest radius that fit around the largest one, with ~30 % margin
        return int(max(16, math.ceil(1.3 * 0.74 * (ratio**3 - (m.radius_max / m.radius_min) ** 3))))

    def contacts(self) -> Contacts:
        """Allocate the contact lists and history for this model (a rebuild is due on the first step)."""
        m = self.model
        n, dev = m.sphere_count, m.device
        cap = int(self.options.neighbor_capacity or self.default_neighbor_capacity())
        mcap = int(self.options.mesh_capacity) if m.wall_count else 1
        planes = max(m.plane_count, 1)
        history = self.features.history_type

        def slots(k, dtype):
            check_row_bytes(n, dtype)
            return wp.zeros((k, n), dtype=dtype, device=dev)

        partner_key, partner_count = _st.partner_tables(m.clump_count, dev)
        c = Contacts(
            neighbor_capacity=cap,
            mesh_capacity=mcap,
            skin=self.skin,
            neighbor_count=wp.zeros(n, dtype=int, device=dev),
            neighbor_index=slots(cap, int),
            neighbor_history=slots(cap, history),
            plane_history=slots(planes, history),
            mesh_count=wp.zeros(n, dtype=int, device=dev),
            mesh_face=slots(mcap, int),
            mesh_history=slots(mcap, history),
            neighbor_live=wp.zeros(n, dtype=wp.uint64, device=dev),
            plane_live=wp.zeros(n, dtype=wp.uint64, device=dev),
            wall_build_pose=wp.zeros(max(m.wall_count, 1), dtype=wp.transform, device=dev),
            build_x=wp.zeros(n, dtype=wp.vec3, device=dev),
            rebuild=wp.ones(1, dtype=int, device=dev),
            overflow=wp.zeros(1, dtype=int, device=dev),
            partner_key=partner_key,
            partner_count=partner_count,
            cells=_nb.cell_grid(n, dev),
        )
        for name in _nb.LIST_ARRAYS:
            c.scratch[name] = wp.zeros_like(getattr(c, name))
        return c

    def _check_contacts(self, contacts: Contacts) -> None:
        """Contacts must hold the history layout the kernels are compiled for (``features`` set after
        :meth:`contacts` allocated them would not match)."""
        want = self.features.history_type
        if contacts.neighbor_history.dtype is not want:
            raise InputError(
                f"Solver: contacts hold history of type {contacts.neighbor_history.dtype.__name__}, but the "
                f"kernels are compiled for {want.__name__} (features {self.features}); allocate them with "
                "Solver.contacts() after setting Solver.features"
            )

    # the step -------------------------------------------------------------------------------
    def rebuild(self, state: State, contacts: Contacts) -> None:
        """Remove the bodies that left the domain, rebuild the candidate lists from ``state`` and carry the
        history over."""
        m, c = self.model, contacts
        _st.launch_retire_escaped(m, state)
        inv_cell = _nb.cell_inverse_size(m, self.skin)
        _nb.launch_clear_cells(m, c, self._buffers.rebuild_count)
        _nb.launch_count_cells(m, state, c, inv_cell)
        _nb.launch_sum_cell_tiles(m, c)
        _nb.launch_scan_cell_tile_sums(m, c)
        _nb.launch_scan_cells(m, c)
        _nb.launch_sort_spheres(m, state, c, inv_cell)
        _nb.launch_build_contacts(m, state, c, features=self.features, inv_cell=inv_cell, skin=self.skin)
        _nb.launch_commit_contacts(m, c)
        wp.copy(c.wall_build_pose, state.wall_pose)
        c.rebuild.zero_()

    def step(
        self, state_in: State, state_out: State, control: Control | None, contacts: Contacts, dt: float | None = None
    ) -> None:
        """Advance ``state_in`` by one step into ``state_out`` (rebuilding the lists first if due)."""
        self._check_contacts(contacts)
        for name in State.TWIN_SHARED:
            setattr(state_out, name, getattr(state_in, name))
        self._set_time(state_in.time)
        self._step(state_in, state_out, control, contacts, dt)

    def _set_time(self, time: float) -> None:
        """Device time of the next step's start (host write, never inside a capture)."""
        self._buffers.time.assign(np.array([time, time], dtype=np.float64))

    def _step(
        self, state_in: State, state_out: State, control: Control | None, contacts: Contacts, dt: float | None = None
    ) -> None:
        if not state_in.half_step:
            self._start(state_in, control, contacts)
        wp.capture_if(contacts.rebuild, on_true=lambda: self.rebuild(state_in, contacts))
        self._advance(state_in, state_out, contacts, control, dt)

    def _start(self, state: State, control: Control | None, contacts: Contacts) -> None:
        """Complete a fresh state: wall poses at its time, clump angular momenta from angular velocities."""
        m = self.model
        if m.wall_count:
            self._move_walls(state, control, contacts, rebuild=self._buffers.no_rebuild)
        if m.clump_count:
            _st.launch_init_clumps(m, state)

    def _move_walls(self, state: State, control: Control | None, contacts: Contacts, rebuild) -> None:
        """Poses of the walls at the device time[1] into ``state``; ``rebuild`` is flagged when they moved far."""
        m = self.model
        _st.launch_move_walls(
            m, control or self.control, contacts, state, self._buffers, skin=self.skin, rebuild=rebuild
        )
        if m.attached_count:
            _st.launch_follow_walls(m, contacts, state, skin=self.skin, rebuild=rebuild)

    def _advance(
        self,
        state_in: State,
        state_out: State,
        contacts: Contacts,
        control: Control | None = None,
        dt: float | None = None,
    ) -> None:
        """Forces and integration of one step, without the rebuild check."""
        m, c = self.model, contacts
        dt = self.dt if dt is None else float(dt)
        kick = dt if state_in.half_step else 0.5 * dt
        if self._kick_next is not None:
            # the step changed: leapfrog's kick spans half of each (v lives at half steps); a fresh state has
            # no half step to span
            kick = self._kick_next if state_in.half_step else kick
            self._kick_next = None
        o, b = self.options, self._buffers
        _st.launch_begin_step(m, b, dt)
        _st.launch_step_spheres(
            m,
            c,
            state_in,
            state_out,
            b,
            features=self.features,
            dt=dt,
            kick=kick,
            skin=self.skin,
            velocity_limit=o.velocity_limit,
            impact_speed_min=o.impact_speed_min,
        )
        if self.features.share_mass:
            _st.launch_roll_partners(m, c, b)
        if m.clump_count:
            _st.launch_integrate_clumps(
                m,
                c,
                state_in,
                state_out,
                b,
                features=self.features,
                dt=dt,
                kick=kick,
                skin=self.skin,
                velocity_limit=o.velocity_limit,
            )
        if m.plane_count + m.wall_count:
            _st.launch_sum_wall_forces(m, state_in, state_out, b, dt)
        if state_out.sphere_active is not state_in.sphere_active:
            wp.copy(state_out.sphere_active, state_in.sphere_active)
        if m.wall_count:
            self._move_walls(state_out, control, c, rebuild=c.rebuild)
        state_out.time = state_in.time + dt
        state_out.step = state_in.step + 1
        state_out.half_step = True

    # driver ---------------------------------------------------------------------------------
    def run(
        self,
        state: State,
        contacts: Contacts,
        steps: int,
        control: Control | None = None,
        use_graph: bool | None = None,
    ) -> State:
        """Take ``steps`` steps starting from ``state``; returns the final state (``state`` or its twin).

        On CPU, pairs of steps are replayed as one captured graph with the rebuild as a conditional
        node; on CUDA, blocks of :attr:`cuda_graph_steps` steps. Where CUDA cannot capture that (a driver
        without conditional nodes), each step is a captured graph and the host reads the 4-byte rebuild
        flag between steps. Blow-ups and overflows are checked once at the end and raise
        :class:`SimulationError`.
        """
        if int(steps) <= 0:
            return state
        state = self._enqueue(state, contacts, steps, control, use_graph)
        self.check(contacts)
        return state

    def run_iter(self, state: State, contacts: Contacts, steps: int, control: Control | None = None):
        """:meth:`run` as a generator: it yields once, when the steps are queued on the device's current stream
        and before the host waits for them (the check), so a caller can queue other launches' work on other
        streams meanwhile (:func:`drive` runs it to the end). Returns the final state."""
        state = self._enqueue(state, contacts, steps, control, None)
        yield
        self.check(contacts)
        return state

    def _enqueue(
        self, state: State, contacts: Contacts, steps: int, control: Control | None, use_graph: bool | None
    ) -> State:
        """Queue ``steps`` steps (see :meth:`run`) without waiting for them, except where the host must read the
        rebuild flag (the fallback without conditional graph nodes); the caller checks."""
        self._check_contacts(contacts)
        steps = int(steps)
        if steps <= 0:
            return state
        t0, step0 = state.time, state.step
        self._buffers.stiffness_max.zero_()
        if self._spare is None or self._spare.sphere_x.shape != state.sphere_x.shape:
            self._spare = self.model.state()
        # the twin shares the activity flags (they change only at a release or a removal, never within a
        # step), the impact records (running sums every step adds to) and the removal counts
        self._spare.sphere_active = state.sphere_active
        for name in State.TWIN_SHARED:
            setattr(self._spare, name, getattr(state, name))
        a, b = state, self._spare
        if use_graph is None:
            # CUDA graphs on GPU; Warp's CPU capture removes the Python launch overhead on CPU too
            use_graph = steps >= 64
        self._set_time(state.time)
        done = 0
        # the first step runs eagerly: it applies the half kick (or the kick across a change of step), which a
        # replayed step does not
        if not a.half_step or self._kick_next is not None or (use_graph and not self._graph):
            self._step(a, b, control, contacts)
            a, b = b, a
            done = 1
        if use_graph and self._is_cuda and self.cuda_graph_steps and steps - done >= 2:
            # CUDA: blocks of cuda_graph_steps steps replayed as one graph with the rebuild as a conditional node
            # (the cell grid is built by plain kernels), so the host never waits on the GPU between blocks
            block = self.cuda_graph_steps
            if steps - done >= block:
                try:
                    (graph,) = self._graphs(
                        a, b, contacts, control, block, lambda: self._alternate(a, b, block, control, contacts)
                    )
                except Exception as exc:  # an older driver without conditional nodes: host-read path
                    warnings.warn(
                        f"CUDA graph with a conditional rebuild failed ({exc}); "
                        "falling back to one host read of the rebuild flag per step",
                        stacklevel=2,
                    )
                    self.cuda_graph_steps = 0
                    self._graph, graph = {}, None
                if graph is not None:
                    blocks = (steps - done) // block
                    for _ in range(blocks):
                        wp.capture_launch(graph)
                    done += blocks * block
            if self.cuda_graph_steps and steps - done >= 2:
                # the remainder in pairs: a run ends at an output tick or a release, so each has a remainder, and
                # stepped eagerly it cost the host more than the blocks (15 launches a step)
                pair = self._pair_graph(a, b, contacts, control)
                pairs = (steps - done) // 2
                for _ in range(pairs):
                    wp.capture_launch(pair)
                done += 2 * pairs
            # the last step of an odd remainder is stepped eagerly below, parity kept
            a.time = t0 + done * self.dt
            a.step = step0 + done
        if use_graph and self._is_cuda and not self.cuda_graph_steps:
            # fallback: the host reads the rebuild flag each step (one 4-byte copy) and replays a captured step
            # without the rebuild, one graph per direction
            graphs = self._graphs(
                a,
                b,
                contacts,
                control,
                "host reads",
                lambda: self._advance(a, b, contacts, control),
                lambda: self._advance(b, a, contacts, control),
            )
            parity = 0
            while done < steps:
                wp.copy(self._flag_host, contacts.rebuild)
                wp.synchronize_stream()
                if host(self._flag_host)[0]:
                    self.rebuild(a if parity == 0 else b, contacts)
                wp.capture_launch(graphs[parity])
                parity ^= 1
                done += 1
            if parity:
                a, b = b, a
            a.time, a.step, a.half_step = t0 + steps * self.dt, step0 + steps, True
        elif use_graph and not self._is_cuda and steps - done >= 2:
            before = int(host(self._buffers.clock)[0])
            graph = self._pair_graph(a, b, contacts, control)
            # Warp's CPU capture also executes what it records: count those two steps
            if int(host(self._buffers.clock)[0]) != before:
                a.time += 2 * self.dt
                a.step += 2
                done += 2
            pairs = max(steps - done, 0) // 2
            for _ in range(pairs):
                wp.capture_launch(graph)
            a.time += 2 * pairs * self.dt
            a.step += 2 * pairs
            done += 2 * pairs
        while done < steps:
            self._step(a, b, control, contacts)
            a, b = b, a
            done += 1
        self._spare = b
        a.released = state.released
        return a

    def _alternate(self, a: State, b: State, steps: int, control: Control | None, contacts: Contacts) -> None:
        """Take ``steps`` steps back and forth between the twin states: a -> b, b -> a, ..."""
        for i in range(steps):
            src, dst = (a, b) if i % 2 == 0 else (b, a)
            self._step(src, dst, control, contacts)

    def _pair_graph(self, a: State, b: State, contacts: Contacts, control: Control | None):
        """The captured graph of two steps, a -> b -> a (see :meth:`_graphs`)."""
        return self._graphs(a, b, contacts, control, 2, lambda: self._alternate(a, b, 2, control, contacts))[0]

    def _graphs(self, a: State, b: State, contacts: Contacts, control: Control | None, kind, *records) -> list:
        """The graphs captured for these twin states, contacts, control and ``kind`` of replay, else one
        captured per recording function (each launches steps between ``a`` and ``b``). Recording also advances
        the states' host-side times and step counts: they are put back, since a replay does not advance them."""
        key = (id(a), id(b), id(contacts), id(control), kind)
        if key not in self._graph:
            a.half_step = b.half_step = True
            graphs = []
            for record in records:
                times = (a.time, a.step, b.time, b.step)
                try:
                    with wp.ScopedCapture(device=self.model.device) as cap:
                        record()
                finally:
                    a.time, a.step, b.time, b.step = times
                graphs.append(cap.graph)
            self._graph[key] = (graphs, (a, b, contacts, control))
        return self._graph[key][0]

    def release(
        self, state: State, contacts: Contacts, sphere_index, sphere_x, sphere_v, clump_index, clump_x, clump_q, clump_v
    ) -> None:
        """Activate parked particles at the given places (host arrays; spheres shape (n,), (n, 3); clumps
        (k,), (k, 3), (k, 4) quaternions (x, y, z, w), (k, 3)) and flag a rebuild."""
        _st.launch_place_bodies(
            self.model, contacts, state, sphere_index, sphere_x, sphere_v, clump_index, clump_x, clump_q, clump_v
        )

    def settle_worlds(self, state: State, worlds) -> None:
        """Hold every sphere of ``worlds`` (world indices, host ints) where it is from the next step on
        (``SphereActivity.SETTLED``): a world whose scene says it has settled costs a launch nothing more while its
        others still move, and ends as it would alone (not moved on by its launch-mates' time). Irreversible."""
        if len(worlds):
            _st.launch_settle_worlds(self.model, state, worlds)

    @property
    def rebuild_count(self) -> int:
        """Neighbour-list rebuilds this solver has made (a host read: synchronises)."""
        return int(host(self._buffers.rebuild_count)[0])

    def advance(self, state: State, contacts: Contacts, duration: float, control: Control | None = None) -> State:
        """Run for ``duration`` [s], releasing the model's dynamic factories on their schedules.

        Between releases the run is one :meth:`run` call (captured, no host sync per step). At a release the
        host reads the positions once, places the batch clear of every particle in each world (the same random
        stream in every world, so world k matches a solo run) and activates it. A batch the region cannot take
        whole is partly deferred by one interval. ``state.released[f]["count"]`` counts the particles factory f
        has released so far.
        """
        return drive(self.advance_iter(state, contacts, duration, control))

    def advance_iter(self, state: State, contacts: Contacts, duration: float, control: Control | None = None):
        """:meth:`advance` as a generator that yields whenever steps are queued and the host is about to wait
        for them (see :meth:`run_iter`); returns the final state."""
        end = state.time + float(duration)
        while True:
            self._adapt_dt()
            eps = 0.5 * self.dt
            due = {
                f: t
                for f in range(len(self.model.factories))
                if (t := self._next_release(state, f)) is not None and t <= end + eps
            }
            if not due:
                steps = int(round((end - state.time) / self.dt))
                if steps > 0:
                    state = yield from self.run_iter(state, contacts, steps, control)
                return state
            t_next = min(due.values())
            steps = int(round((t_next - state.time) / self.dt))
            if steps > 0:
                state = yield from self.run_iter(state, contacts, steps, control)
            for f, t in due.items():
                if t <= state.time + eps:
                    self._release_factory(state, contacts, f)

    def _adapt_dt(self) -> None:
        """Halve the step while the last run's margin exceeded ``dt_margin`` (at most ``dt_levels`` halvings), or
        double it when doubling leaves a third of ``dt_margin`` spare; the margin scales with dt."""
        levels, target, margin = int(self.options.dt_levels), self.options.dt_margin, self.step_margin
        if not levels or margin is None:
            return
        level = self.dt_level
        while margin > target and level < levels:
            level, margin = level + 1, margin / 2
        if level == self.dt_level and level > 0 and 2 * margin <= DT_RAISE * target:
            level -= 1
        self.set_dt_level(level)

    def dt_state(self) -> dict:
        """What decides the next step (a checkpoint keeps it): the level, the last run's margin, the largest."""
        return {"level": self.dt_level, "margin": self.step_margin, "margin_max": self.step_margin_max}

    def restore_dt_state(self, saved: dict) -> None:
        """Continue at a saved :meth:`dt_state`: the state saved with it already stepped at that level, so no
        kick across a change of step follows."""
        self.dt_level = int(saved["level"])
        self.dt = self.dt_base / 2.0**self.dt_level
        self.step_margin, self.step_margin_max = saved["margin"], float(saved["margin_max"])
        self._kick_next, self._graph = None, {}

    def set_dt_level(self, level: int) -> None:
        """Step at ``dt_base / 2**level`` from the next step on; that step's kick spans half of the old step and
        half of the new one."""
        level = int(level)
        if level == self.dt_level:
            return
        dt_old, self.dt_level = self.dt, level
        self.dt = self.dt_base / 2.0**level
        self.step_margin = None if self.step_margin is None else self.step_margin * self.dt / dt_old
        self._kick_next = 0.5 * (dt_old + self.dt)
        self._graph = {}

    def _next_release(self, state: State, f: int) -> float | None:
        """Time of factory f's next release [s], or None once it released everything."""
        rec = self.model.factories[f]
        log = state.released.setdefault(f, {"count": 0, "retry": -math.inf})
        if log["count"] >= rec["count"]:
            return None
        plan = rec["factory"].plan()
        cum = np.cumsum([c for _, c in plan])
        t_plan = plan[int(np.searchsorted(cum, log["count"], side="right"))][0]
        return max(t_plan, log["retry"], state.time)

    def _release_factory(self, state: State, contacts: Contacts, f: int) -> None:
        m = self.model
        rec = m.factories[f]
        fac = rec["factory"]
        log = state.released[f]
        done = log["count"]
        plan = fac.plan()
        cum = np.cumsum([c for _, c in plan])
        times = np.array([t for t, _ in plan])
        target = (
            int(cum[np.searchsorted(times, state.time + 0.5 * self.dt, side="right") - 1])
            if times[0] <= state.time + 0.5 * self.dt
            else 0
        )
        want = max(target - done, 0)
        if want == 0:
            return
        x_all = host(state.sphere_x)
        active = host(state.sphere_active).astype(bool)
        radius = host(m.sphere_radius)
        world_of = host(m.sphere_world)
        placed = None
        s_idx, s_x, s_v, c_idx, c_x, c_q, c_v = [], [], [], [], [], [], []
        # the worlds that hold this factory (a stacked Model's scenes each have their own)
        for w in np.flatnonzero(rec["world_first"] >= 0):
            mine = active & (world_of == w)
            ws = 0 if m.world_seed is None else int(m.world_seed[w])
            # a world seed gives that world its own placement stream (repeats of a design point differ)
            rng = None if ws == 0 else fac.world_rng(ws, done)
            x, _ = fac.place(rng, want, x_all[mine], radius[mine], first=done)
            placed = len(x) if placed is None else min(placed, len(x))
            k = np.arange(done, done + len(x))
            vel = np.tile(np.asarray(fac.initial_velocity, dtype=np.float64), (len(x), 1))
            if rec["kind"] == "sphere":
                s_idx.append(rec["world_first"][w] + k)
                s_x.append(x)
                s_v.append(vel)
            else:
                c_idx.append(rec["world_first"][w] + k)
                c_x.append(x)
                c_q.append(np.asarray(fac.quaternions)[k])
                c_v.append(vel)

        # every world releases the same particles: the fewest any world could place
        def cut(parts, width=None):
            if not parts:
                return np.zeros((0, width) if width else 0)
            return np.concatenate([p[:placed] for p in parts])

        self.release(
            state, contacts, cut(s_idx), cut(s_x, 3), cut(s_v, 3), cut(c_idx), cut(c_x, 3), cut(c_q, 4), cut(c_v, 3)
        )
        log["count"] = done + int(placed)
        # a crowded region defers the rest of its batch by one interval
        log["retry"] = state.time + fac.interval if placed < want else -math.inf

    def check(self, contacts: Contacts) -> None:
        """Raise SimulationError if a blow-up or a capacity overflow was flagged (three small host reads, the
        third the stiffest sphere's Omega^2 for :attr:`step_margin`).

        An overflow drops contacts, so spheres may pass into each other and blow up; a sphere that blew up
        may also crowd into others and overflow their lists: when both are flagged the message gives both.
        """
        blow = host(self._buffers.blowup)
        self.step_margin = 0.5 * self.dt * math.sqrt(max(float(host(self._buffers.stiffness_max)[0]), 0.0))
        self.step_margin_max = max(self.step_margin_max, self.step_margin)
        flags = int(host(contacts.overflow)[0])
        dropped = ""
        if flags:
            what = []
            if flags & Overflow.NEIGHBOR:
                what.append(f"neighbor_capacity = {contacts.neighbor_capacity}")
            if flags & Overflow.MESH:
                what.append(f"mesh_capacity = {contacts.mesh_capacity}")
            dropped = f"contact capacity exceeded ({', '.join(what)}): contacts were dropped; raise it in SolverOptions"
        if blow[1] != _st.BLOWUP_NONE:
            i = int(blow[0])
            world = int(host(self.model.sphere_world)[i])
            cause = f"; also {dropped}" if dropped else ""
            raise SimulationError(
                f"blow-up at step {int(blow[1])}: sphere {i} (world {world}) has a non-finite state or a speed "
                f"above velocity_limit = {self.options.velocity_limit} m/s; reduce dt (now {self.dt:.3g} s, "
                f"Rayleigh time {self.model.rayleigh_time:.3g} s) or check the inputs{cause}"
            )
        if dropped:
            raise SimulationError(dropped)
