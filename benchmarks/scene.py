"""Scene images at interactive rates: ``softshadow bench --what scene``.

The Dowling paper's view of the real Stanford dragon (MIT remesh, 41,384 faces) and its levels
of detail (``softshadow.lod_series``, halving to the paper's 300 faces), 640 x 480, one sample
per pixel, lit by the sun (its soft shadow: the renderer's expanded shadow volume, k = 0.01),
one slide projector (the paper's lattice slide, 15 cycles, amplitude 1, its own shadow map)
and an ambient term (``softshadow.MaskingScene``). Each level is drawn by ``FrameRenderer``
(``render_frame``: forward only, the image ``render_scene`` draws) for ``frames`` frames after
``warmup`` frames, the sun moving by 0.05 degrees of azimuth every frame: every frame makes the
sun's shadow map, plan and penumbra anew. The camera, the object and the projector stay, so the
renderer keeps the projector's shadow map, what each pixel sees and the projector's light at
every pixel (it keeps each while its inputs stay); the same frames with the projector moving by
1 mm every frame (its map and light made anew each time) and with the camera moving by 1 mm
every frame (what each pixel sees and the projector's light made anew each time) are timed
beside them. ``frame_ms`` is the median wall time per frame, with the steps' medians beside it,
with two threads (the renderer's default) and with one. The differentiable ``render_scene`` of
the full dragon is timed warm beside it (the median of its third to sixth calls).

The levels' two-thread frames (``frame_ms``, the figure the levels are compared by) are timed
interleaved: each level keeps its own renderer, and the levels take turns, ``BLOCK`` frames
each, in one order and then the reverse, round after round (``INTERLEAVED_FRAMES`` frames of
each level, the sun turning as above), so that all of them see the same state of a shared
machine (timed one level after the other, the 2-core test machine's speed drifted by up to a
fifth between levels; in the same order every round, the first level and the last, a round
apart, still read it at different times). The other settings are timed level by level.

Rows (key ``scene``): faces (the full mesh's), level (the face count drawn), width, height,
frame_ms (median wall time per frame, two threads), frame_ms_rounds (its median in each round of
the interleaved timing), frame_min_ms, frame_max_ms (the worst frame after warm-up), frame_cpu_ms
(median CPU time of the process per frame, all threads), the same with one thread
(``..._one_thread``), with the projector moving (``..._projector_moves``, two threads) and with
the camera moving (``..._camera_moves``, two threads), steps_ms and
steps_ms_camera_moves (the steps' median wall times, ``softshadow.internal.FRAME_STEPS``), and
the load average before and after the level. The summary gives the 300-face level's frame over the
full dragon's (``coarsest_over_full``: medians; ``..._rounds``: round by round; ``..._cpu``: CPU
times) and what the machine gave of its second core after each round of the interleaved timing
(``two_thread_slowdown_rounds``, ``benchmarks.environment.two_thread_slowdown``: about 1 with two
cores free, towards 2 with one core's worth), their median (``two_thread_slowdown``) and, where it
read above ``ONE_CORE_SLOWDOWN``, or when a quarter of the rounds were slow (``spell_warnings``),
``warnings``.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

__all__ = ["bench_scene", "machine_warnings", "scene_table", "spell_warnings", "SCENE_LEVELS"]

#: The levels drawn: the full dragon, then halving to the paper's coarsest.
SCENE_LEVELS = (20000, 10000, 5000, 2500, 1000, 300)

#: Frames a level draws in its turn of the interleaved timing.
BLOCK = 8

#: Frames each level draws in the interleaved timing (``frame_ms``): 64 rounds of ``BLOCK``,
#: about 45 s for the seven levels on the 2-core test machine. The test machine has slow spells of
#: ten seconds or more, in which every two-thread frame of every level takes about 5 ms longer:
#: over 16 rounds (12 s) one spell could cover half the rounds and move the medians (the 300-face
#: level's by half, the full dragon's by a quarter); over 64 it covers a few.
INTERLEAVED_FRAMES = 512


def bench_scene(quick: bool = False, progress=None) -> dict:
    from softshadow import FrameRenderer, MaskingScene, Pose, SoftShadowModel, lod_series, one_blas_thread, \
        render_scene

    from .environment import load_average, two_thread_slowdown
    from .meshes import mit_dragon
    frames, warmup = (8, 3) if quick else (48, 5)
    # The interleaved frames: an even number of BLOCKs (rounds both ways), over a span several
    # times the machine's slow spells (see INTERLEAVED_FRAMES), so that they fall in few rounds.
    interleaved = frames if quick else INTERLEAVED_FRAMES
    scene = MaskingScene()
    mesh = mit_dragon(full=True)
    levels = lod_series(mesh, (len(mesh.faces), *SCENE_LEVELS))
    proj = scene.projector(1.0, 15.0)
    lights = scene.lights(0.01)
    camera = scene.camera()
    models = [SoftShadowModel.from_mesh(level.mesh) for level in levels]

    def draw(renderer, model, i: int, moving=None):
        """Frame i (the sun 0.05 degrees further each frame): its wall and CPU ms and steps."""
        sun = scene.sun_at(azimuth_offset_deg=0.05 * i)
        projector = (dataclasses.replace(proj, position=proj.position + (0.001 * i, 0.0, 0.0))
                     if moving == "projector" else proj)
        view = dataclasses.replace(camera, t=camera.t + (0.001 * i, 0.0, 0.0)) if moving == "camera" else camera
        t, c = time.perf_counter(), time.process_time()
        frame = renderer.render(view, model, Pose(), lights, sun, [projector], object_albedo=scene.albedo,
                                ground_albedo=scene.albedo)
        return 1e3 * (time.perf_counter() - t), 1e3 * (time.process_time() - c), frame.milliseconds

    rows = [{"faces": int(len(mesh.faces)), "level": int(level.faces), "width": camera.width,
             "height": camera.height} for level in levels]
    with one_blas_thread():
        # The two-thread frames of all levels, interleaved (see above).
        if progress:
            progress(f"bench scene: {len(levels)} levels interleaved, 2 threads")
        renderers = [FrameRenderer(threads=2) for _ in levels]
        timed = [[] for _ in levels]
        slowdown = []  # the machine's second core, after each round (``two_thread_slowdown``)
        load_before = load_average()
        try:
            for renderer, model in zip(renderers, models):
                for i in range(warmup):
                    draw(renderer, model, i)
            rounds = -(-interleaved // BLOCK)
            for r in range(rounds):
                for j in (range(len(levels)) if r % 2 == 0 else reversed(range(len(levels)))):
                    for b in range(BLOCK):
                        timed[j].append(draw(renderers[j], models[j], warmup + r * BLOCK + b))
                slowdown.append(two_thread_slowdown())
                if progress:  # between rounds, outside the timed frames
                    progress(f"bench scene: {len(levels)} levels interleaved, 2 threads, round {r + 1} of {rounds}")
        finally:
            for renderer in renderers:
                renderer.close()
        del renderers  # their buffers (tens of megabytes each) not kept through the timings below
        load_after = load_average()
        for row, samples in zip(rows, timed):
            row["load_before"], row["load_after_interleaved"] = load_before, load_after
            _summarise(row, "frame_ms", samples)
            # Each round's median: a slow spell of the machine shows as rounds slower than the rest.
            row["frame_ms_rounds"] = [round(float(np.median([w for w, _, _ in samples[a:a + BLOCK]])), 2)
                                      for a in range(0, len(samples), BLOCK)]
            row["steps_ms"] = _median_steps(samples)
        for row, level, model in zip(rows, levels, models):
            for threads, moving in ((1, None), (2, "projector"), (2, "camera")):
                if progress:
                    progress(f"bench scene: {level.faces:,} faces, {threads} thread(s)"
                             + (f", the {moving} moving" if moving else ""))
                renderer = FrameRenderer(threads=threads)
                try:
                    samples = [draw(renderer, model, i, moving) for i in range(warmup + frames)][warmup:]
                finally:
                    renderer.close()
                key = f"frame_ms_{moving}_moves" if moving else "frame_ms_one_thread"
                _summarise(row, key, samples)
                if moving == "camera":
                    row["steps_ms_camera_moves"] = _median_steps(samples)
            row["load_after"] = load_average()
        # The differentiable path, warm, for comparison.
        model = SoftShadowModel.from_mesh(mesh)
        times = []
        for _ in range(2 if quick else 6):
            t = time.perf_counter()
            out = render_scene(camera, model, Pose(), lights, scene.sun_at(), [proj], object_albedo=scene.albedo,
                               ground_albedo=scene.albedo, range_k_max=float(lights.range_k))
            np.asarray(out.image)
            times.append(1e3 * (time.perf_counter() - t))
    full = next(r for r in rows if r["level"] == r["faces"])
    coarse = min(rows, key=lambda r: r["level"])
    # The second call still settles (tens of ms slower than the later ones): the last ones count.
    return {"scene": rows, "render_scene_ms": round(float(np.median(times[1 if quick else 2:])), 1),
            "settings": {"frames": frames, "interleaved_frames": interleaved, "block": BLOCK, "warmup": warmup,
                         "sun": scene.sun_description(), "range_k": float(lights.range_k), "slide": "sine, 15 cycles, amplitude 1",
                         "shadow_px": int(proj.shadow_px)},
            "summary": {"full_frame_ms": full["frame_ms"], "coarsest_level": coarse["level"],
                        "worst_frame_ms": max(r[k] for r in rows for k in r if k.startswith("frame_max_ms")),
                        "coarsest_frame_ms": coarse["frame_ms"],
                        "coarsest_over_full": round(coarse["frame_ms"] / full["frame_ms"], 3),
                        "coarsest_over_full_rounds": [round(c / f, 3) for c, f in zip(coarse["frame_ms_rounds"],
                                                                                      full["frame_ms_rounds"])],
                        "two_thread_slowdown": round(float(np.median(slowdown)), 2),
                        "two_thread_slowdown_rounds": slowdown,
                        "warnings": machine_warnings(slowdown) + spell_warnings(coarse["frame_ms_rounds"]),
                        "coarsest_over_full_cpu": round(coarse["frame_cpu_ms"] / full["frame_cpu_ms"], 3),
                        "full_frame_ms_camera_moves": full["frame_ms_camera_moves"],
                        "coarsest_frame_ms_camera_moves": coarse["frame_ms_camera_moves"],
                        "coarsest_over_full_camera_moves": round(coarse["frame_ms_camera_moves"]
                                                                 / full["frame_ms_camera_moves"], 3)}}


#: ``two_thread_slowdown``'s median above which the run had about one core's worth (measured on the
#: 2-core test machine: 1.04-1.08 alone, 1.98-2.02 beside one busy process).
ONE_CORE_SLOWDOWN = 1.5


def machine_warnings(slowdown_rounds: list) -> list[str]:
    """What the reader of the frame times should know about the machine they ran on (empty: it
    gave both cores): from ``two_thread_slowdown`` after each interleaved round."""
    median = float(np.median(slowdown_rounds))
    busy = sum(x > ONE_CORE_SLOWDOWN for x in slowdown_rounds)
    if median > ONE_CORE_SLOWDOWN:
        return [f"the machine gave about one core's worth (two_thread_slowdown {median:.2f}, about 1 with two cores "
                "free): another process was busy, and the frames took about their CPU time"]
    if busy:
        return [f"the machine gave about one core's worth in {busy} of {len(slowdown_rounds)} rounds "
                f"(two_thread_slowdown above {ONE_CORE_SLOWDOWN})"]
    return []


#: A round of the interleaved timing is slow when its median frame of the coarsest level is this
#: many times the lower quartile of that level's rounds (a spell may cover half of them): a slow
#: spell of the machine (on the 2-core test machine, 1.4-1.6 times in a spell, within 1.1 otherwise).
SLOW_ROUND = 1.25


def spell_warnings(coarsest_rounds: list) -> list[str]:
    """A warning when a quarter of the rounds or more were slow (``SLOW_ROUND``): a slow spell of the
    machine long enough to move the medians (it adds about the same time to the frames of every
    level, so the coarsest level's share of the full dragon's time reads high)."""
    usual = float(np.percentile(coarsest_rounds, 25))
    slow = sum(x > SLOW_ROUND * usual for x in coarsest_rounds)
    if slow and 4 * slow >= len(coarsest_rounds):
        return [f"{slow} of {len(coarsest_rounds)} rounds were slow (the coarsest level's frame over {SLOW_ROUND} "
                "times its lower quartile): a slow spell of the machine, which reads in the medians"]
    return []


def _summarise(row: dict, key: str, samples: list) -> None:
    """The median, fastest and slowest wall ms and the median CPU ms of samples (wall, CPU, steps)
    into row under key and its variants."""
    times = [w for w, _, _ in samples]
    row[key] = round(float(np.median(times)), 2)
    row[key.replace("frame_ms", "frame_min_ms")] = round(float(np.min(times)), 2)
    # The worst frame after warm-up: a compile (a new array shape) would show here.
    row[key.replace("frame_ms", "frame_max_ms")] = round(float(np.max(times)), 2)
    # The process's CPU time per frame (all its threads, XLA's included): what the frame costs the
    # machine, less moved by the neighbours than the wall time.
    row[key.replace("frame_ms", "frame_cpu_ms")] = round(float(np.median([c for _, c, _ in samples])), 2)


def _median_steps(samples: list) -> dict:
    steps = [s for _, _, s in samples]
    return {k: round(float(np.median([s.get(k, 0.0) for s in steps])), 2) for k in steps[0]}


def scene_table(result: dict) -> str:
    """The Markdown table of ``bench_scene``'s rows (docs/level_of_detail.md)."""
    lines = ["| faces drawn | frame ms, 2 threads (min) | CPU ms per frame | frame ms, 1 thread (min) | "
             "CPU ms per frame | projector moving: frame ms, 2 threads (CPU ms) | "
             "camera moving: frame ms, 2 threads (CPU ms) | "
             "steps ms, 2 threads: visibility / sun plan / sun band / shading | the same, camera moving | "
             "load before |",
             "|---:|---:|---:|---:|---:|---:|---:|---|---|---|"]
    for r in result["scene"]:
        s = r["steps_ms"]
        load = ", ".join(f"{x:.1f}" for x in r["load_before"]) if r.get("load_before") else "?"
        lines.append(f"| {r['level']:,} | {r['frame_ms']:.1f} ({r['frame_min_ms']:.1f}) | {r['frame_cpu_ms']:.1f} | "
                     f"{r['frame_ms_one_thread']:.1f} ({r['frame_min_ms_one_thread']:.1f}) | "
                     f"{r['frame_cpu_ms_one_thread']:.1f} | {r['frame_ms_projector_moves']:.1f} "
                     f"({r['frame_cpu_ms_projector_moves']:.1f}) | {r['frame_ms_camera_moves']:.1f} "
                     f"({r['frame_cpu_ms_camera_moves']:.1f}) | {_steps(s)} | {_steps(r['steps_ms_camera_moves'])} | "
                     f"{load} |")
    return "\n".join(lines)


def _steps(s: dict) -> str:
    return " / ".join(f"{s.get(k, 0.0):.1f}" for k in ("visibility", "sun_plan", "sun_band", "shading"))
