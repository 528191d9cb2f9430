"""Reading keys back inside Blender, the same way in 3.4, 4.5 and 5.0 (imported by the check scripts)."""

import re

BONE_ROTATION = re.compile(r'pose\.bones\["(.+)"\]\.rotation_quaternion')


def fcurves(obj) -> list:
    """The F-curves animating `obj`, wherever this Blender keeps them: in the Action itself (3.4)
    or in the channelbag of the object's slot of a layered Action (4.4 and later; 5.0 has no other)."""
    data = obj.animation_data
    if data is None or data.action is None:
        return []
    slot = getattr(data, "action_slot", None)
    if slot is not None:
        from bpy_extras.anim_utils import action_get_channelbag_for_slot

        channelbag = action_get_channelbag_for_slot(data.action, slot)
        return list(channelbag.fcurves) if channelbag is not None else []
    return list(data.action.fcurves)


def rotation_keys(obj) -> dict[str, list[float]]:
    """Per bone of an armature object, the frames keyed on its rotation (its first quaternion curve)."""
    keys = {}
    for curve in fcurves(obj):
        match = BONE_ROTATION.fullmatch(curve.data_path)
        if match and curve.array_index == 0:
            keys[match.group(1)] = [point.co.x for point in curve.keyframe_points]
    return keys
