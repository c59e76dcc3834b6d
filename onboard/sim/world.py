"""What the simulator adds to the world format (``shared.world``): it must be able to render the world.

Every texture must be one of the simulator's (``onboard.sim.textures``) and every picture a built-in
one or a readable image file next to the world file; and the robot's camera must fit under the
ceiling. A world that fails raises ``WorldError`` naming the key, as the format's own checks do.
"""

from __future__ import annotations

from pathlib import Path

from onboard.sim import textures
from shared.geometry import HeadMount
from shared.world import DEFAULT_ROBOT_RADIUS_M, World, WorldError
from shared.world import load_world as load_world_file


def load_world(path_or_name: str | Path, *, robot_radius_m: float = DEFAULT_ROBOT_RADIUS_M,
               mount: HeadMount | None = None) -> World:
    """A bundled world by name (``"paper-lab"``) or a world file, checked for rendering too, and,
    given the robot's ``mount``, for the robot fitting in it."""
    world = load_world_file(path_or_name, robot_radius_m=robot_radius_m)
    try:
        check_renderable(world)
        if mount is not None:
            check_fits(world, mount)
    except WorldError as exc:
        raise WorldError(f"{exc} [in {path_or_name}]") from exc
    return world


def check_renderable(world: World) -> None:
    """Raise ``WorldError`` for a texture the simulator does not have or a picture it cannot load."""
    room = world.room
    named = [("room.texture", room.texture), ("room.floor_texture", room.floor_texture),
             ("room.ceiling_texture", room.ceiling_texture)]
    named += [(f"obstacle[{i}].texture", box.texture) for i, box in enumerate(world.obstacles)]
    known = textures.texture_names()
    for key, name in named:
        if name is not None and name not in known:
            raise WorldError(f"{key}: unknown texture {name!r} (known: {', '.join(known)})")
    pictures = [("target.picture", world.target.picture)]
    pictures += [(f"poster[{i}].picture", poster.picture) for i, poster in enumerate(world.posters)]
    for key, name in pictures:
        try:
            textures.load_picture(name, world.base_dir)
        except textures.PictureError as exc:
            raise WorldError(f"{key}: {exc}") from exc


def check_fits(world: World, mount: HeadMount) -> None:
    """Raise ``WorldError`` if the robot's cameras (at the tilt axis, ``mount.height_m`` up) do not fit
    under the ceiling: the format cannot know the robot, so a low room is only refused here."""
    height = world.room.size_m[2]
    if mount.height_m >= height:
        raise WorldError(f"room.size: the room is {height:g} m high, and the robot's cameras are "
                         f"{mount.height_m:g} m above the floor: the robot does not fit")
