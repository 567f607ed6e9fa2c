"""Scenes kept in the 3D view's renderer (a mixin of :class:`winder_gui.views.view3d.MandrelView3D`).

A laminate's layers each have their own surface (the layer wound on the one before) and their own paths,
eye path and band.  Building those actors costs a software-GL frame several hundred ms (line and band
meshes, uploads, the scalar bar); playing a program on from layer to layer, or jumping to a layer, would
stall that long at every layer.  So each surface and each path set keeps its actors in the renderer once
made — a *scene*: the one shown under the actors' usual names (``mandrel``, ``paths``, ``band`` ...),
the others hidden and renamed ``name@key`` — and showing a layer again is a visibility swap.  The
results presenter prepares every layer's scenes in advance (:meth:`SceneCacheMixin.prepare_scenes`),
so even the first play through a laminate swaps only.  At most :data:`MAX_SCENES` of each kind are kept
(least recently shown dropped).
"""

from __future__ import annotations

from collections import OrderedDict
from typing import Any

MAX_SCENES = 12
"""Most surface scenes, and most path scenes, kept in the renderer."""
SURFACE_ACTORS = ("mandrel", "mandrel_lod")
PATH_ACTORS = ("paths", "paths_lod", "eye_path_all", "eye_path_lod", "band")


class SceneCacheMixin:
    """Surface and path scenes kept in the renderer, swapped by visibility (needs ``plotter``)."""

    plotter: Any
    backend: str
    _path_meshes: dict[str, Any]
    _band: Any

    def _scenes_init(self) -> None:
        self._scenes: dict[str, OrderedDict[tuple, dict[str, Any]]] = {"surface": OrderedDict(), "paths": OrderedDict()}
        self._scene_shown: dict[str, tuple | None] = {"surface": None, "paths": None}
        self._scene_serial = 0
        self._prepared: dict[str, set[tuple]] = {"surface": set(), "paths": set()}
        """Keys of the scenes made ahead for the current result (kept; the others go when a new one is made)."""

    def scene_count(self, kind: str) -> int:
        """How many ``kind`` (``surface`` / ``paths``) scenes the renderer holds."""
        return len(self._scenes[kind])

    def _park_scene(self, kind: str) -> None:
        """Hide the shown ``kind`` scene and rename its actors out of the way (kept for a later swap)."""
        key = self._scene_shown[kind]
        self._scene_shown[kind] = None
        scene = self._scenes[kind].get(key) if key is not None else None
        if scene is None:
            return
        for name, actor in scene["actors"].items():
            actor.SetVisibility(False)
            actor.name = f"{name}@{scene['serial']}"

    def _show_scene(self, kind: str, key: tuple) -> dict[str, Any] | None:
        """Show the kept ``kind`` scene ``key`` under the usual names (its actors as they were made;
        the per-render choices of detail follow); ``None`` when there is none."""
        scene = self._scenes[kind].get(key)
        if scene is None:
            return None
        self._scenes[kind].move_to_end(key)
        for name, actor in scene["actors"].items():
            actor.name = name
            actor.SetVisibility(scene["visible"].get(name, True))
        self._scene_shown[kind] = key
        return scene

    def _keep_scene(self, kind: str, key: tuple, names: tuple[str, ...], **state: Any) -> dict[str, Any]:
        """Register the actors just made under ``names`` as the shown ``kind`` scene ``key``."""
        actors = self.plotter.actors
        self._scene_serial += 1
        found = {n: actors[n] for n in names if n in actors}
        scene = {"serial": self._scene_serial, "actors": found,
                 "visible": {n: bool(a.GetVisibility()) for n, a in found.items()}, **state}
        old = self._scenes[kind].pop(key, None)
        if old is not None:
            self._drop_actors(old)
        self._scenes[kind][key] = scene
        self._scene_shown[kind] = key
        while len(self._scenes[kind]) > MAX_SCENES:
            oldest = next(iter(self._scenes[kind]))
            if oldest == key:
                break
            self._drop_actors(self._scenes[kind].pop(oldest))
        return scene

    def _drop_actors(self, scene: dict[str, Any]) -> None:
        for actor in scene["actors"].values():
            self.plotter.remove_actor(actor, render=False)

    def _drop_unprepared(self, kind: str) -> None:
        """Drop the kept ``kind`` scenes not made ahead for the current result (an earlier run's)."""
        for key in [k for k in self._scenes[kind] if k not in self._prepared[kind]]:
            scene = self._scenes[kind].pop(key)
            if self._scene_shown[kind] == key:
                self._scene_shown[kind] = None
            self._drop_actors(scene)

    def forget_scenes(self, kind: str, keep: tuple | None = None) -> None:
        """Remove every kept ``kind`` scene but ``keep`` (e.g. the paths scenes of another colouring)."""
        for key in list(self._scenes[kind]):
            if key != keep:
                scene = self._scenes[kind].pop(key)
                if self._scene_shown[kind] == key:
                    self._scene_shown[kind] = None
                self._drop_actors(scene)

    def prepare_scenes(self, items: list[tuple[Any, Any]],
                       build: bool = True) -> None:
        """Make the surface and path scenes of ``(data, paths)`` pairs (a laminate's layers) ahead, kept
        hidden, so showing one later is a visibility swap; the scenes of earlier results are dropped.
        ``build=False``: only note them (and drop the others); :meth:`prepare_scene` makes each."""
        if self.backend != "vtk" or self.plotter is None:
            return
        surf_keys = {("surface", id(d)) for d, _p in items if d is not None}
        path_keys = {self._paths_key(p) for _d, p in items if p is not None}
        self._prepared = {"surface": surf_keys, "paths": path_keys}
        for kind, keep in (("surface", surf_keys), ("paths", path_keys)):
            shown = self._scene_shown[kind]
            for key in [k for k in self._scenes[kind] if k not in keep and k != shown]:
                self._drop_actors(self._scenes[kind].pop(key))
        if build:
            for d, p in items:
                self.prepare_scene(d, p)

    def prepare_scene(self, data: Any, paths: Any) -> None:
        """Make the scenes of one surface and path set ahead (hidden; nothing shown changes)."""
        if self.backend != "vtk" or self.plotter is None:
            return
        self.plotter.suppress_rendering = True
        try:
            for kind, key, obj, build in (("surface", ("surface", id(data)), data, self._build_surface_scene),
                                          ("paths", self._paths_key(paths) if paths is not None else None, paths,
                                           self._build_paths_scene)):
                if obj is None or key in self._scenes[kind]:
                    continue
                if kind == "paths" and obj.line_xyz.shape[0] < 2:
                    continue
                shown = self._scene_shown[kind]
                saved = self._park_keep_state(kind)
                meshes, band = self._path_meshes, self._band
                build(obj)
                self._park_scene(kind)
                self._path_meshes, self._band = meshes, band
                if shown is not None:
                    self._show_scene(kind, shown)
                    self._restore_state(kind, saved)
        finally:
            self.plotter.suppress_rendering = False

    def _park_keep_state(self, kind: str) -> dict[str, bool]:
        key = self._scene_shown[kind]
        scene = self._scenes[kind].get(key) if key is not None else None
        state = {n: bool(a.GetVisibility()) for n, a in scene["actors"].items()} if scene else {}
        self._park_scene(kind)
        return state

    def _restore_state(self, kind: str, state: dict[str, bool]) -> None:
        scene = self._scenes[kind].get(self._scene_shown[kind])
        if scene is not None:
            for n, on in state.items():
                scene["actors"][n].SetVisibility(on)
