"""When the autopilot or the link takes the vehicle from the recovery: the autopilot's own failsafe
(ridden out, re-engaged from where the vehicle is, or left to the autopilot when it lands or flies
home), a failsafe that will not give the companion its mode back (the autopilot's land mode where the
vehicle is), and a lost MAVLink link (the last setpoint streamed while the link is waited for). Each
policy returns the recovery's :class:`Outcome` when it ends the recovery, None when the recovery goes
on; the machine (:mod:`companion.recovery.machine`) decides what going on means."""

from __future__ import annotations

from companion.control import (
    MAV_STATE_CRITICAL,
    AutopilotFailsafe,
    CommandRefused,
    ControlError,
    TelemetryLost,
)
from companion.recovery.core import MAX_REENGAGE, SEVERITY_CRITICAL, Outcome, RecoveryContext, State


class Handover:
    """The policies for the autopilot's failsafes and a lost link (module docstring), on the
    recovery's context."""

    def __init__(self, ctx: RecoveryContext) -> None:
        self.ctx = ctx
        self.reengaged = 0  # re-engagements after the autopilot's own failsafe (MAX_REENGAGE)

    def in_charge(self) -> str | None:
        """The mode of an autopilot failsafe that lands or flies home and has the vehicle now
        (system status critical): the companion does not take the vehicle from it."""
        s = self.ctx.tm.state
        if s.system_status != MAV_STATE_CRITICAL:
            return None
        return self.ctx.ctl.flavour.lands_or_returns(s.custom_mode)

    async def on_failsafe(self, exc: AutopilotFailsafe) -> Outcome | None:
        """Policy for the autopilot leaving the companion's mode in a failsafe of its own. A failsafe
        may clear by itself (PX4's offboard-loss fallback, once setpoints flow again) or hold before it
        acts (PX4 holds for ``COM_BAT_ACT_T`` / ``COM_FAIL_ACT_T`` before its battery or other action,
        and a command in that time is a user takeover that cancels it). So first, for
        ``failsafe_grace_s``, the companion streams a hold where the vehicle is and commands no mode.
        Back in the companion's mode meanwhile: the recovery goes on (None). Then in a mode that lands
        or flies home (a battery, GPS, geofence or link failsafe), or already down: the autopilot keeps
        the vehicle (:meth:`leave_to_autopilot`). Still holding (PX4's POSCTL or AUTO.LOITER,
        ArduPilot's LOITER or BRAKE): re-engaged from where it is (:meth:`reengage`)."""
        ctx = self.ctx
        flavour = ctx.ctl.flavour
        seen = flavour.mode_name(exc.custom_mode)
        fields = {"round": ctx.round, "state": ctx.state.value, "mode": seen}
        ctx.record.record_event("autopilot_failsafe", fields)
        ctx.say(4, f"autopilot failsafe: {seen}; waiting {ctx.p.failsafe_grace_s:g} s for it to clear")
        if await ctx.ctl.ride_out_failsafe(ctx.p.failsafe_grace_s):
            ctx.record.record_event("autopilot_failsafe_cleared", fields)
            ctx.say(5, f"the autopilot's failsafe cleared ({seen} -> back to the companion): going on")
            return None
        now = ctx.tm.state
        mode = flavour.lands_or_returns(now.custom_mode)
        if now.on_ground and mode is None:
            # down already (an autopilot may leave its landing mode as it disarms): the landing mode
            # it came down in, if the grace period saw one
            landed_in = [m for m in map(flavour.lands_or_returns, ctx.ctl.failsafe_modes) if m is not None]
            mode = landed_in[-1] if landed_in else seen
        if mode is not None:
            return await self.leave_to_autopilot(mode)
        try:
            await self.reengage(AutopilotFailsafe(now.custom_mode))
        except CommandRefused as refused:
            # the companion's mode cannot run (no position estimate: PX4 refuses OFFBOARD and holds in
            # ALTCTL, drifting, for as long as the battery lasts): the least bad is the autopilot's own
            # landing where the vehicle is
            return await self.land_in_place(flavour.mode_name(now.custom_mode), refused)
        return None

    async def land_in_place(self, holding: str, refused: CommandRefused) -> Outcome:
        """The autopilot's failsafe holds and will not give the companion its mode back: ask for the
        autopilot's land mode where the vehicle is and watch it down (``land_timeout_s``); refused
        too, the autopilot keeps the vehicle (:meth:`leave_to_autopilot`)."""
        ctx = self.ctx
        ctx.set_state(State.LAND)
        ctx.say(
            SEVERITY_CRITICAL,
            f"autopilot failsafe holds in {holding} and refuses the companion's mode ({refused}): "
            "asking it to land where it is",
        )
        ctx.record.record_event(
            "land_in_place", {"round": ctx.round, "holding": holding, "why": str(refused)}
        )
        try:
            await ctx.ctl.land(ctx.p.land_timeout_s)
        except CommandRefused as again:
            # refused too (real PX4 takes no AUTO.LAND without a position; its own blind descent is
            # what is left): the autopilot keeps the vehicle, watched down
            ctx.say(4, f"land mode refused as well ({again})")
            return await self.leave_to_autopilot(holding)
        ctx.set_state(State.LANDED)
        return Outcome(State.LANDED, ctx.round, None, f"landed where it was: the autopilot held in {holding}")

    async def leave_to_autopilot(self, mode: str) -> Outcome:
        """The autopilot's failsafe keeps the vehicle: the companion stops its setpoint stream, says so
        (critical) and never takes the vehicle back. A landing (or a return home, which ends in one)
        is watched to the ground for ``land_timeout_s`` so that the record ends with it."""
        ctx = self.ctx
        await ctx.ctl.release()
        ctx.set_state(State.ABORTED)
        ctx.say(SEVERITY_CRITICAL, f"autopilot failsafe: {mode}; the autopilot keeps control")
        ctx.record.record_event("released", {"round": ctx.round, "to": mode})
        if await ctx.ctl.wait_on_ground(ctx.p.land_timeout_s):
            ctx.set_state(State.LANDED)
            return Outcome(State.LANDED, ctx.round, None, f"the autopilot's failsafe landed it ({mode})")
        return Outcome(State.ABORTED, ctx.round, None, f"the autopilot's failsafe has it ({mode})")

    async def reengage(self, exc: AutopilotFailsafe) -> None:
        """Policy: the autopilot's own failsafe (e.g. a lost setpoint stream) is re-engaged from where
        the vehicle is, ``MAX_REENGAGE`` times at most; then the autopilot keeps control."""
        self.reengaged += 1
        if self.reengaged > MAX_REENGAGE:
            raise ControlError(f"{exc}; not re-engaging again") from exc
        self.ctx.say(4, f"{exc}: re-engaging")
        await self.ctx.ctl.engage()

    async def ride_out_link_loss(self, exc: TelemetryLost) -> Outcome | None:
        """Policy for a lost MAVLink link: keep streaming the last setpoint and wait up to
        ``link_loss_s`` for telemetry. Meanwhile the autopilot holds (PX4's offboard-loss failsafe
        after COM_OF_LOSS_T; ArduPilot's GUIDED keeps the last target). When the link returns: a
        vehicle that came down meanwhile ends the recovery; a failsafe that holds is re-engaged from
        where the vehicle is, one that lands or returns keeps the vehicle; someone else's mode is a
        takeover. Then an interrupted descent goes on at the
        same site, confirmed again first; otherwise the next round starts. No telemetry within
        ``link_loss_s``: the companion stops commanding and leaves the vehicle to the autopilot."""
        ctx = self.ctx
        ctx.record.record_event("link_lost", {"round": ctx.round, "state": ctx.state.value})
        ctx.say(3, f"link to the autopilot lost ({exc}): holding, waiting {ctx.p.link_loss_s:.0f} s")
        try:
            silent_s = await ctx.ctl.await_link(ctx.p.link_loss_s)
        except TelemetryLost as lost:
            raise ControlError(f"{lost}: leaving the vehicle to the autopilot") from lost
        except AutopilotFailsafe as failsafe:  # heartbeats without positions: the estimator lost them
            ctx.say(4, "the autopilot is heard but sends no position: its estimator has none")
            return await self.on_failsafe(failsafe)
        s = ctx.tm.state
        ctx.record.record_event(
            "link_restored",
            {"round": ctx.round, "silent_s": round(silent_s, 2), "custom_mode": s.custom_mode},
        )
        ctx.say(5, f"link back after {silent_s:.1f} s")
        if s.on_ground:
            ctx.set_state(State.LANDED)
            ctx.say(4, "the vehicle came down while the link was lost")
            return Outcome(State.LANDED, ctx.round, None, "landed by the autopilot during a link loss")
        try:
            ctx.ctl.check_interruption()
        except AutopilotFailsafe as failsafe:
            return await self.on_failsafe(failsafe)
        return None
