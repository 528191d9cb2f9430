"""The outputs the live loop drives: OSC targets (flat or VMC profile) and the BVH recorder."""

from __future__ import annotations

import numpy as np

from ..errors import UserError
from ..models.modelfile import Model
from ..motion.features import forward_direction
from ..terminal import Console
from ..motion.kinematics import ChannelStream
from ..synthesis.posing import Frame
from .background import Background
from .flat import FlatProfile, footfall_datagrams
from .humanoid import guess_humanoid
from .osc import Datagrams, OscTarget, UdpOut, unbundled
from .recorder import BvhRecorder
from .vmc import VmcProfile


class OscOutput:
    """One OSC target. It sends the pose of its `character`, or (a crowd's flat profile) every
    character's: the live loop hands it what it asks for.

    A crowd large enough to share its frame's work over the cores sends from its profile's thread
    (`FlatProfile.sending`, a `Background`): its frame's datagrams take milliseconds of the
    kernel's time, which then run beside the next frame's work instead of before it. The thread
    is the profile's, not the target's, because every target of a profile sends from the
    profile's one buffer. A smaller crowd, and one character, send in the loop's thread, where a
    hand-over would cost more than the sending."""

    def __init__(self, target: OscTarget, profile, console: Console, character: int = 0):
        self.name = f"osc {target}"
        self.profile = profile
        self.character = character
        self.whole_crowd = getattr(profile, "whole_crowd", False)
        self.bundled = target.bundled
        self.out = UdpOut(target, console)
        self.background: Background | None = getattr(profile, "sending", None) if self.whole_crowd else None
        self._error: Exception | None = None  # what this target's last sending on the thread raised

    def prepare(self, frame: Frame) -> tuple[list[bytes], list[bytes] | Datagrams]:
        """The frame's footfalls (flat profile; sent first: the frame's /walk/frame comes last),
        and the frame itself (a crowd's flat profile written in place, sent from there)."""
        if self.background is not None:  # the last frame's datagrams are sent from the buffer this one is written into
            self.background.wait()
        pose = frame.crowd if self.whole_crowd else frame.pose(self.character)
        footfalls = []
        if frame.footfalls and isinstance(self.profile, FlatProfile):
            whose = range(frame.crowd.rotations.shape[0]) if self.whole_crowd else range(self.character, self.character + 1)
            footfalls = footfall_datagrams(frame.footfalls, whose)
        if self.bundled and hasattr(self.profile, "encode"):
            return footfalls, self.profile.encode(pose, frame.echo)
        datagrams = self.profile.datagrams(pose, frame.echo)
        return (footfalls, datagrams) if self.bundled else (unbundled(footfalls), unbundled(datagrams))

    def send(self, prepared: tuple[list[bytes], list[bytes] | Datagrams]) -> None:
        if self.background is None:
            self._send(prepared)
            return
        error, self._error = self._error, None  # the last frame's sending's (it has ended: `prepare` waited for it)
        self.background.hand(lambda: self._send_noting(prepared))
        if error is not None:  # counted against this target now, with this frame handed over still
            raise error

    def _send_noting(self, prepared: tuple[list[bytes], list[bytes] | Datagrams]) -> None:
        """`_send` on the sending thread: what it raises is kept for this target's next `send`."""
        try:
            self._send(prepared)
        except Exception as error:
            self._error = error

    def _send(self, prepared: tuple[list[bytes], list[bytes] | Datagrams]) -> None:
        footfalls, datagrams = prepared
        if footfalls:
            self.out.send(footfalls)
        self.out.send(datagrams)

    def close(self) -> None:
        try:
            if self.background is not None:  # the last frame sent before the socket closes
                self.background.close()
                error, self._error = self._error, None
                if error is not None:
                    raise error
        finally:
            self.out.close()


class RecorderOutput:
    def __init__(self, path: str, model: Model, fps: float, replace: bool = False, character: int = 0):
        self.name = f"bvh {path}"
        self.character = character  # of a crowd, the one recorded
        self.channels = ChannelStream(model.layout.skeleton)
        self.recorder = BvhRecorder(path, model.layout.skeleton, fps, replace)

    def prepare(self, frame: Frame):
        pose = frame.pose(self.character)
        return self.channels.next(pose.rotations, pose.translations)

    def send(self, channels) -> None:
        self.recorder.write(channels)

    def close(self) -> None:
        self.recorder.close()


def make_profile(kind: str, model: Model, humanoid: dict[str, str] | None = None, vmc_root: str = "hips",
                 fingers: bool = True, characters: int = 1):
    """`humanoid`: the VMC profile's joint-to-bone map (`read_humanoid`), None: guessed from the
    joints' names. `characters`: the flat profile of a crowd carries them all (a VMC target takes one)."""
    layout = model.layout
    if kind == "flat":
        return FlatProfile(layout.skeleton.names, layout.root, characters)
    mapping = humanoid if humanoid is not None else guess_humanoid(layout.skeleton)
    if not mapping:  # joints named joint01, joint02, ...: nothing to send a humanoid, nor to rest in a T-pose
        names = layout.skeleton.names
        raise UserError(f"no joint name of the model's skeleton ({', '.join(names[:4])}{', ...' if len(names) > 4 else ''}) "
                        "says which humanoid bone it is, as the VMC profile and the T-pose rest need: give --humanoid "
                        "BONES.toml ([bones] \"joint\" = \"Hips\", ...: docs/osc.md); without it `run` sends the flat "
                        "profile (--osc HOST:PORT/flat) and `skeleton --template` writes the model's own rest")
    means = [m.means[..., : layout.dimension].reshape(-1, layout.dimension) for m in (model.average, model.styles)]
    return VmcProfile(layout, mapping, forward_direction(model.average.means[..., : layout.dimension]),
                      stance=np.concatenate(means), root=vmc_root, fingers=fingers)
