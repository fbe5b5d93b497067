"""Generate ``scenes/humanoid.usda``: the wresdyn reference biped, authored by this project.

A 1.3 m, ~36 kg humanoid with a pelvis base, two 6-DoF legs (hip yaw, hip roll, hip pitch, knee,
ankle pitch, ankle roll), a waist-yaw torso joint and two 4-DoF arms (shoulder pitch, roll, yaw,
elbow): 21 actuated revolute joints. Link masses, gains, effort limits and reflected rotor inertia
(armature) are of the size published for 1.3 m electric humanoids of this class (e.g. Unitree G1:
1.32 m, ~35 kg; hip/knee gains 100-200 N*m/rad, ankle/arm gains 20-60, armature 0.01-0.03 kg*m^2).

Every body frame is aligned with the world frame in the zero pose and sits at its parent joint,
so the zero pose is the robot standing straight with arms down. Axes: x forward, y left, z up.
Each sole carries a named site (``left_sole``, ``right_sole``) used as the IK frame.

Run ``python scenes/make_humanoid.py`` to regenerate; the generated file is committed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from pxr import Gf, Sdf, Usd, UsdGeom, UsdPhysics


@dataclass(frozen=True)
class Link:
    name: str
    parent: str | None
    joint: str | None
    """Name of the revolute joint that connects this link to its parent (``None`` for the base)."""
    axis: str
    """Joint axis in the (world-aligned) link frame: "X" (roll), "Y" (pitch) or "Z" (yaw)."""
    offset: tuple[float, float, float]
    """Joint position in the parent link frame [m]."""
    mass: float
    """Link mass [kg]."""
    com: tuple[float, float, float]
    """Centre of mass in the link frame [m]."""
    box: tuple[float, float, float]
    """Size of the uniform box whose inertia approximates the link's [m]; also its collision shape."""
    lower: float = 0.0
    """Joint lower limit [deg] (USD physics convention)."""
    upper: float = 0.0
    """Joint upper limit [deg]."""
    kp: float = 0.0
    """PD stiffness [N*m/rad]."""
    kd: float = 0.0
    """PD damping [N*m*s/rad]."""
    effort: float = 0.0
    """Effort (torque) limit [N*m]."""
    armature: float = 0.0
    """Reflected rotor inertia about the joint axis [kg*m^2]."""


def _leg(side: str, y: float) -> list[Link]:
    s = 1.0 if side == "left" else -1.0
    p = f"{side}_"
    # hip roll range is asymmetric: a leg swings outward more than across the body
    roll_lo, roll_hi = (-30.0, 60.0) if s > 0 else (-60.0, 30.0)
    yaw_lo, yaw_hi = (-45.0, 45.0)
    return [
        Link(p + "hip_yaw_link", "pelvis", p + "hip_yaw", "Z", (0.0, s * y, -0.06), 1.0, (0.0, 0.0, -0.03),
             (0.08, 0.08, 0.08), yaw_lo, yaw_hi, 100.0, 2.5, 88.0, 0.012),
        Link(p + "hip_roll_link", p + "hip_yaw_link", p + "hip_roll", "X", (0.0, 0.0, -0.07), 1.2, (0.0, 0.0, -0.02),
             (0.1, 0.08, 0.08), roll_lo, roll_hi, 100.0, 2.5, 88.0, 0.012),
        Link(p + "thigh", p + "hip_roll_link", p + "hip_pitch", "Y", (0.0, 0.0, -0.03), 3.0, (0.0, 0.0, -0.13),
             (0.11, 0.11, 0.28), -120.0, 60.0, 150.0, 4.0, 88.0, 0.025),
        Link(p + "shin", p + "thigh", p + "knee", "Y", (0.0, 0.0, -0.29), 2.0, (0.0, 0.0, -0.13),
             (0.09, 0.09, 0.28), 0.0, 150.0, 200.0, 5.0, 139.0, 0.025),
        Link(p + "ankle_pitch_link", p + "shin", p + "ankle_pitch", "Y", (0.0, 0.0, -0.29), 0.1, (0.0, 0.0, 0.0),
             (0.04, 0.04, 0.04), -50.0, 30.0, 40.0, 2.0, 50.0, 0.01),
        Link(p + "foot", p + "ankle_pitch_link", p + "ankle_roll", "X", (0.0, 0.0, -0.02), 0.7, (0.02, 0.0, -0.02),
             (0.22, 0.09, 0.04), -15.0, 15.0, 40.0, 2.0, 50.0, 0.01),
    ]


def _arm(side: str, y: float) -> list[Link]:
    s = 1.0 if side == "left" else -1.0
    p = f"{side}_"
    roll_lo, roll_hi = (-15.0, 120.0) if s > 0 else (-120.0, 15.0)
    return [
        Link(p + "shoulder_pitch_link", "torso", p + "shoulder_pitch", "Y", (0.0, s * y, 0.27), 0.5, (0.0, s * 0.02, 0.0),
             (0.06, 0.06, 0.06), -150.0, 90.0, 40.0, 1.0, 25.0, 0.01),
        Link(p + "shoulder_roll_link", p + "shoulder_pitch_link", p + "shoulder_roll", "X", (0.0, s * 0.05, 0.0), 0.5,
             (0.0, 0.0, -0.03), (0.06, 0.06, 0.07), roll_lo, roll_hi, 40.0, 1.0, 25.0, 0.01),
        Link(p + "upper_arm", p + "shoulder_roll_link", p + "shoulder_yaw", "Z", (0.0, 0.0, -0.06), 0.8, (0.0, 0.0, -0.08),
             (0.07, 0.07, 0.18), -90.0, 90.0, 30.0, 1.0, 25.0, 0.01),
        Link(p + "forearm", p + "upper_arm", p + "elbow", "Y", (0.0, 0.0, -0.18), 0.6, (0.0, 0.0, -0.1),
             (0.06, 0.06, 0.22), -120.0, 10.0, 30.0, 1.0, 25.0, 0.01),
    ]


def links() -> list[Link]:
    """All links in depth-first order: pelvis, legs, torso, arms."""
    base = [Link("pelvis", None, None, "Z", (0.0, 0.0, 0.0), 5.0, (0.0, 0.0, 0.0), (0.14, 0.26, 0.12))]
    torso = [Link("torso", "pelvis", "waist_yaw", "Z", (0.0, 0.0, 0.08), 9.5, (0.0, 0.0, 0.18), (0.16, 0.26, 0.38),
                  -90.0, 90.0, 150.0, 4.0, 88.0, 0.025)]
    return base + _leg("left", 0.09) + _leg("right", 0.09) + torso + _arm("left", 0.13) + _arm("right", 0.13)


PELVIS_HEIGHT = 0.80
"""Pelvis height above the floor in the zero pose [m]: the leg chain is 0.80 m, so the soles are on z = 0."""


def _box_inertia(m: float, size: tuple[float, float, float]) -> Gf.Vec3f:
    x, y, z = size
    return Gf.Vec3f(m * (y * y + z * z) / 12.0, m * (x * x + z * z) / 12.0, m * (x * x + y * y) / 12.0)


def build(path: Path) -> Usd.Stage:
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    UsdPhysics.SetStageKilogramsPerUnit(stage, 1.0)
    scene = UsdPhysics.Scene.Define(stage, "/physicsScene")
    scene.CreateGravityDirectionAttr(Gf.Vec3f(0.0, 0.0, -1.0))
    scene.CreateGravityMagnitudeAttr(9.81)
    root = UsdGeom.Xform.Define(stage, "/humanoid")
    stage.SetDefaultPrim(root.GetPrim())
    stage.GetRootLayer().documentation = "wresdyn reference humanoid, generated by scenes/make_humanoid.py"

    world_pos: dict[str, Gf.Vec3d] = {}
    for link in links():
        parent = world_pos.get(link.parent, Gf.Vec3d(0.0, 0.0, PELVIS_HEIGHT))
        pos = parent + Gf.Vec3d(*link.offset) if link.parent else parent
        world_pos[link.name] = pos
        body_path = f"/humanoid/{link.name}"
        body = UsdGeom.Xform.Define(stage, body_path)
        body.AddTranslateOp().Set(pos)
        prim = body.GetPrim()
        UsdPhysics.RigidBodyAPI.Apply(prim)
        mass = UsdPhysics.MassAPI.Apply(prim)
        mass.CreateMassAttr(link.mass)
        mass.CreateCenterOfMassAttr(Gf.Vec3f(*link.com))
        mass.CreateDiagonalInertiaAttr(_box_inertia(link.mass, link.box))
        mass.CreatePrincipalAxesAttr(Gf.Quatf(1.0, 0.0, 0.0, 0.0))
        if link.parent is None:
            UsdPhysics.ArticulationRootAPI.Apply(prim)
        # collision: a box around the centre of mass; visual: the same box, render-only
        col = UsdGeom.Cube.Define(stage, f"{body_path}/collision")
        col.CreateSizeAttr(1.0)
        col.AddTranslateOp().Set(Gf.Vec3d(*link.com))
        col.AddScaleOp().Set(Gf.Vec3f(*link.box))
        col.CreatePurposeAttr(UsdGeom.Tokens.guide)
        UsdPhysics.CollisionAPI.Apply(col.GetPrim())
        vis = UsdGeom.Cube.Define(stage, f"{body_path}/visual")
        vis.CreateSizeAttr(1.0)
        vis.AddTranslateOp().Set(Gf.Vec3d(*link.com))
        vis.AddScaleOp().Set(Gf.Vec3f(*[0.95 * s for s in link.box]))
        vis.CreateDisplayColorAttr([Gf.Vec3f(0.35, 0.45, 0.6)])
        if link.name.endswith("foot"):
            side = link.name.split("_")[0]
            site = UsdGeom.Sphere.Define(stage, f"{body_path}/{side}_sole")
            site.CreateRadiusAttr(0.005)
            # sole centre: below the ankle-roll axis at the bottom face of the foot box
            site.AddTranslateOp().Set(Gf.Vec3d(link.com[0], 0.0, link.com[2] - link.box[2] / 2.0))
            site.GetPrim().AddAppliedSchema("NewtonSiteAPI")
        if link.joint is None:
            continue
        joint = UsdPhysics.RevoluteJoint.Define(stage, f"/humanoid/joints/{link.joint}")
        joint.CreateBody0Rel().SetTargets([f"/humanoid/{link.parent}"])
        joint.CreateBody1Rel().SetTargets([body_path])
        joint.CreateLocalPos0Attr(Gf.Vec3f(*link.offset))
        joint.CreateLocalRot0Attr(Gf.Quatf(1.0, 0.0, 0.0, 0.0))
        joint.CreateLocalPos1Attr(Gf.Vec3f(0.0, 0.0, 0.0))
        joint.CreateLocalRot1Attr(Gf.Quatf(1.0, 0.0, 0.0, 0.0))
        joint.CreateAxisAttr(link.axis)
        joint.CreateLowerLimitAttr(link.lower)
        joint.CreateUpperLimitAttr(link.upper)
        drive = UsdPhysics.DriveAPI.Apply(joint.GetPrim(), "angular")
        drive.CreateTypeAttr("force")
        # USD angular drive gains are per degree; the Link table is per radian
        drive.CreateStiffnessAttr(link.kp * math.pi / 180.0)
        drive.CreateDampingAttr(link.kd * math.pi / 180.0)
        drive.CreateMaxForceAttr(link.effort)
        drive.CreateTargetPositionAttr(0.0)
        jp = joint.GetPrim()
        jp.AddAppliedSchema("NewtonJointAPI")
        jp.CreateAttribute("newton:armature", Sdf.ValueTypeNames.Float).Set(link.armature)
        jp.CreateAttribute("newton:friction", Sdf.ValueTypeNames.Float).Set(0.0)
    return stage


def write(path: Path) -> None:
    """Generate the humanoid and save it to ``path`` (replacing any existing file)."""
    path = Path(path)
    if path.exists():
        path.unlink()
    stage = build(path)
    stage.GetRootLayer().Save()


if __name__ == "__main__":
    out = Path(__file__).with_name("humanoid.usda")
    write(out)
    total = sum(link.mass for link in links())
    print(f"wrote {out}: {len(links())} links, {len(links()) - 1} joints, {total:.1f} kg")
