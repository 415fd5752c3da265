"""Operators: Refine Lightmap UVs, and removing the material preview it adds.

Run from the UI, the refinement is modal: native work runs on a worker thread
while a timer polls it, Blender's progress indicator moves and Esc cancels.
Run from a script (EXEC_DEFAULT), it blocks. Either way a failed or cancelled
run is rolled back through the job's journal, and a successful one is a
single undo step (bl_options UNDO; the modal run pushes it when it finishes).
"""

import sys
import time

import bpy

from . import panels, pipeline
from .journal import Journal


def _report_outcome(operator, context, outcome, seconds):
    summary = outcome.summary()
    result = context.scene.lmrefine.result
    result.valid = True
    result.objects = ", ".join(outcome.objects)
    result.moved = summary["moved"]
    result.transition_widening = summary["transition_widening"]
    result.density_min = summary["density_min"]
    result.density_max = summary["density_max"]
    result.limited_by = summary["limited_by"]
    result.warnings = len(outcome.warnings)
    result.warning_text = "\n".join(outcome.warnings)  # the panel keeps them after the run
    result.timings = "  ".join(f"{stage} {value:.2f}s" for stage, value in outcome.timings.items())
    result.tessellated = bool(outcome.tessellation)
    result.vertices_added = summary["vertices_added"]
    result.images = summary["images_per_pass"]
    result.shared = "; ".join(f"{name}: {', '.join(objects)}" for name, objects in summary["shared_images"].items())
    result.stages = outcome.stages_asked
    result.effects = "; ".join(f"{name} {e['resolution']}px {e['transition_widening']:.2f}x"
                               for name, e in summary["effects"].items())
    result.stages_kept = summary["stages_kept"]
    # Reports are per map (an object, or an atlas group of several): count and name objects.
    recharted_maps = [name for name, report in outcome.reports.items() if (report.get("rechart") or {}).get("used")]
    recharted = [obj for name in recharted_maps for obj in outcome.atlases.get(name, [name])]
    result.recharted = len(recharted)
    result.stretched = summary["stretched_charts"]
    result.stretched_triangles = summary["stretched_triangles"]
    result.stages_stopped = "; ".join(_stage_stop(name, entry) for name, entry in outcome.stages.items()
                                      if not entry["stages"][-1]["kept"])
    if summary["moved"] == 0:
        result.message = (f"Nothing moved: the refined UV maps of {len(outcome.objects)} object(s) equal their "
                          f"source maps ({seconds:.1f}s; the warnings say why)")
    else:
        still = len(outcome.objects) - summary["moved"]
        across = summary["transition_widening_across"]
        result.message = (f"Refined {len(outcome.objects)} object(s) in {seconds:.1f}s: texels at light changes "
                          f"{summary['transition_widening']:.2f}x their area"
                          + (f" ({across:.2f}x across them)" if across is not None else "")
                          + ", a triangle's texels "
                          # .2g as in the panel: a triangle the repack shrank to 0.0019x does not read "0.00x".
                          f"{summary['density_min']:.2g}x to {summary['density_max']:.3g}x (chart repack included)"
                          + (f"; {still} did not move (see warnings)" if still else ""))
    limits = panels.limit_words(summary["limited_by"])
    if limits:  # the panel's "Limit:" row, in words
        result.message += "; limits: " + ", ".join(f"{short} ({meaning})" for short, meaning in limits)
    result.message += "; " + images_sentence(summary)
    if result.effects:
        result.message += f"; per effect (map side, edges): {result.effects}"
    if recharted:
        result.message += (f"; re-charted from the mesh: {', '.join(recharted)} (the source map gave the "
                           "refiner no room, or its charts folded over sharp edges; the Info log says why)")
    if summary["stretched_charts"]:
        result.message += (f"; {summary['stretched_charts']} chart(s) stretched across their light changes "
                           f"(up to {summary['largest_stretch']:.2f}x, their texel area kept)")
    if summary["stretched_triangles"]:
        result.message += f"; {summary['stretched_triangles']} triangle(s) stretched across their light changes"
    if summary["grown_charts"]:
        result.message += f"; {summary['grown_charts']} chart(s) grown into the space the packing left"
    if outcome.tessellation:
        result.message += f"; tessellation added {summary['vertices_added']} vertices"
    if outcome.stages:
        why = "; ".join(f"{name}: {entry['stopped']}" + ("" if entry.get("repack", True) else
                                                         ", stages 2+ refined inside the charts (no room in the source map)")
                        for name, entry in outcome.stages.items())
        result.message += f"; stages kept: {summary['stages_kept']} of {result.stages} ({why})"
    for name, report in outcome.reports.items():
        sentence = rechart_sentence(report) if name in recharted_maps else not_recharted_sentence(report)
        if sentence:
            operator.report({'INFO'}, f"'{name}': {sentence}")
    for warning in outcome.warnings:
        operator.report({'WARNING'}, warning)
    operator.report({'INFO'}, result.message)


def images_sentence(summary):
    """How many images a run wrote for how many objects, and which objects share which."""
    per_pass, objects, effects = summary["images_per_pass"], summary["objects"], summary["effects"]
    if effects:  # Layouts: Per Effect: each map gets one image per effect, whatever the bake passes
        text = (f"{per_pass * len(effects)} image(s) for {objects} object(s), {per_pass} per effect "
                f"({', '.join(effects)})")
    else:
        text = f"{per_pass} image(s) per pass for {objects} object(s)"
    shared = summary["shared_images"]
    if shared:
        text += " (" + "; ".join(f"{name}_lightmap_*: {', '.join(names)}" for name, names in shared.items()) + ")"
    return text


def _first_effect(report, sentence):
    """With Layouts: Per Effect (a report of "effects"), `sentence` of the first effect that has one, named;
    None when none has."""
    sentences = ((name, sentence(own)) for name, own in report["effects"].items())
    return next((f"{name}: {text}" for name, text in sentences if text), None)


def rechart_sentence(report):
    """Why a map was re-charted and what that is predicted to give, from its refine_uvs report, in the
    panel's words: the core's own note (report["notes"][0]) names its keywords and its error model.
    None where it was not re-charted."""
    if "effects" in report:
        return _first_effect(report, rechart_sentence)
    info = report.get("rechart") or {}
    if not info.get("used"):
        return None
    roomier = (", packed half a texel farther apart than Padding so that their edge texels could shrink"
               if info.get("edge_room") else "")
    source = info.get("predicted_error_source_route")
    instead = (f"{source:.2f}x refining the source map instead" if source is not None else
               f"refining the source map instead: at least {info['source_route_bound']:.2f}x, so it was not "
               "finished")
    return (f"re-charted from the mesh ({info['charts']} charts of faces within {info['angle']:g} "
            f"degrees{roomier}) and refined, because {_rechart_cause(info)}. Predicted lightmap error (blur at "
            f"the light changes): {info['predicted_error']:.2f}x the source map's ({instead}). To keep the source "
            "map's charts, turn off Re-chart if Better (Refinement)")


def _check_words(name):
    """A check refine_uvs says a re-charted map failed against its source map (a key of check_layout's
    report, or 'gutter') in the panel's words, as the core's warnings name it
    (lmrefine.layout_input.PROBLEM_WORDS)."""
    from lmrefine.layout_input import PROBLEM_WORDS

    if name == "gutter":
        return "charts closer than Padding"
    return PROBLEM_WORDS[name][1] if name in PROBLEM_WORDS else name.replace("_", " ")


def not_recharted_sentence(report):
    """Why a map that Re-chart if Better tried to re-chart kept its source map's charts, from its refine_uvs
    report, in the panel's words; None where it was not tried (a source map with room whose charts fold
    over no sharp edge) or was re-charted."""
    if "effects" in report:
        return _first_effect(report, not_recharted_sentence)
    info = report.get("rechart") or {}
    if info.get("used") or not any(note.startswith("not re-charted:") for note in report.get("notes", [])):
        return None
    from lmrefine.rechart_route import REQUIRED_GAIN
    reason = info["reason"]  # the core's words, where neither case below applies
    source = info.get("predicted_error_source_route")
    if info.get("failed"):  # chosen by the model, then failed the source map's checks
        reason = ("the re-charted map had " + ", ".join(_check_words(name) for name in info["failed"])
                  + ", which the source map has not")
    elif "predicted_error" in info and source is not None:  # the model preferred the source map's refinement
        reason = (f"re-charting was predicted to give {info['predicted_error']:.2f}x the source map's lightmap "
                  f"error (blur at the light changes) and refining the source map {source:.2f}x; re-charting "
                  f"needs below {REQUIRED_GAIN:g}x and below the other")
    return (f"not re-charted, though {_rechart_cause(info)}: {reason}. The source map's charts were refined instead")


def _rechart_cause(info):
    """Why the re-chart route was tried on a map (its refine_uvs report's rechart entry)."""
    room = info["room"]
    if room["no_room"]:
        why = (f"its source map gives the refiner no room ({room['charts']} charts for {room['triangles']} "
               f"triangles, {room['room_fraction']:.0%} of its area in triangles with a UV inside their chart: a "
               "UV on a chart's border keeps its place)")
    elif info.get("always"):  # the layout had no room before Tessellate split its triangles
        why = f"its source map's {room['charts']} charts were one face each before Tessellate split their triangles"
    elif info.get("folds"):
        folds = info["folds"]
        smooth = f", {folds['smooth']} of them smooth-shaded" if folds.get("smooth") else ""
        why = (f"its source map's charts fold over {folds['count']} creases sharper than {info['angle']:g} degrees "
               f"({folds['length']:.3g} world units{smooth}), which hold {folds['energy_fraction']:.0%} of its "
               "light changes")
    else:  # a route refused before it looked for folds (Strength 0)
        why = "its source map's charts fold over sharp edges"
    return why


def _stage_stop(name, entry):
    """Short, for the panel: which stage an object stopped at and why (the report has the sentence); the
    panel shows the name and the rest on two rows of at most 23 characters."""
    from lmrefine.metrics import stage_stop_kind
    last = entry["stages"][-1]
    why = stage_stop_kind(last["stage"], last["moved"], last["layout_change"], last["backoff"], last["widening"])
    if why == "settled":
        why = f"moved {last['layout_change']:.1%}" if last["moved"] else "did not move"
    return f"{name}: stage {last['stage']} {why}"


def _rollback(operator, journal):
    try:
        journal.rollback()
    except Exception as error:  # the scene may be half-reverted: say so loudly
        operator.report({'ERROR'}, f"Could not fully revert the scene ({error}): use Edit > Undo")


def _failure_message(error):
    if isinstance(error, pipeline.UserError):
        return str(error)
    text = pipeline.error_text(error)  # no C++ source locations: the console keeps the full text
    if isinstance(error, ValueError):  # lmrefine's own messages name the problem and the fix
        return f"lmrefine: {text}"
    return f"Refinement failed ({type(error).__name__}: {text}); the scene was left unchanged"


def _is_cancel(error):
    if isinstance(error, (pipeline.Cancelled, KeyboardInterrupt)):
        return True
    core = sys.modules.get("lmrefine")  # loaded if a native call could have raised its CancelledError
    return core is not None and isinstance(error, core.CancelledError)


class LMREFINE_OT_refine_uvs(bpy.types.Operator):
    """Refine the lightmap UV map of the selected meshes so light/shadow edges get more texels, then bake"""

    bl_idname = "object.lmrefine_refine_uvs"
    bl_label = "Refine Lightmap UVs"
    bl_options = {'REGISTER', 'UNDO'}

    @classmethod
    def poll(cls, context):
        # Problems (wrong mode, nothing selected, ...) are reported by the operator with the fix,
        # rather than a greyed-out button that does not say why.
        return context.scene is not None and hasattr(context.scene, "lmrefine")

    def _prepare(self, context):
        options = pipeline.settings_snapshot(context.scene.lmrefine)
        targets = pipeline.validate(context, list(context.selected_objects), options)
        return options, targets

    # ------------------------------------------------------------ blocking

    def execute(self, context):
        started = time.perf_counter()
        try:
            options, targets = self._prepare(context)
        except pipeline.UserError as error:
            self.report({'ERROR'}, str(error))
            return {'CANCELLED'}
        journal = Journal()
        wm = context.window_manager
        wm.progress_begin(0.0, 1.0)
        try:
            job = pipeline.run(context, targets, options, journal)
            outcome = pipeline.run_blocking(job, progress=lambda fraction, label: wm.progress_update(fraction))
        except BaseException as error:
            _rollback(self, journal)
            if _is_cancel(error):
                self.report({'WARNING'}, "Cancelled: the scene was left unchanged")
                return {'CANCELLED'}
            self.report({'ERROR'}, _failure_message(error))
            return {'CANCELLED'}
        finally:
            wm.progress_end()
        journal.commit()
        _report_outcome(self, context, outcome, time.perf_counter() - started)
        return {'FINISHED'}

    # --------------------------------------------------------------- modal

    def invoke(self, context, event):
        if bpy.app.background or context.window is None:
            return self.execute(context)  # no event loop to drive a modal run
        self._started = time.perf_counter()
        try:
            options, targets = self._prepare(context)
        except pipeline.UserError as error:
            self.report({'ERROR'}, str(error))
            return {'CANCELLED'}
        self._begin_modal(context, options, targets)
        context.window_manager.modal_handler_add(self)
        return {'RUNNING_MODAL'}

    def _begin_modal(self, context, options, targets):
        """Everything a modal run needs but the handler: the job, its driver, progress and the timer."""
        self._journal = Journal()
        self._driver = pipeline.ThreadedDriver(pipeline.run(context, targets, options, self._journal))
        wm = context.window_manager
        wm.progress_begin(0.0, 1.0)
        self._timer = wm.event_timer_add(0.1, window=context.window)
        self._status(context)

    def modal(self, context, event):
        if event.type == 'ESC' and event.value == 'PRESS':
            self._driver.cancel()
            self._status(context)
        if event.type != 'TIMER':
            return {'RUNNING_MODAL'}  # block other input: the scene must not change under the job
        state = self._driver.poll()
        if state is None:
            context.window_manager.progress_update(self._driver.fraction)
            self._status(context)
            return {'RUNNING_MODAL'}
        kind, value = state
        if kind == "done":
            return self._end(context, None, value)
        return self._end(context, value)

    def _status(self, context):
        if context.workspace is not None:
            context.workspace.status_text_set(
                f"Refine Lightmap UVs: {self._driver.label} ({100.0 * self._driver.fraction:.0f}%), "
                "Esc to cancel")

    def _end(self, context, error, outcome=None):
        wm = context.window_manager
        wm.event_timer_remove(self._timer)
        wm.progress_end()
        if context.workspace is not None:
            context.workspace.status_text_set(None)
        if error is not None:
            _rollback(self, self._journal)
            if _is_cancel(error):
                self.report({'WARNING'}, "Cancelled: the scene was left unchanged")
            else:
                self.report({'ERROR'}, _failure_message(error))
            return {'CANCELLED'}
        self._journal.commit()
        _report_outcome(self, context, outcome, time.perf_counter() - self._started)
        return {'FINISHED'}


class LMREFINE_OT_remove_preview(bpy.types.Operator):
    """Remove the lightmap preview from the selected objects and put back their materials and active UV map"""

    bl_idname = "object.lmrefine_remove_preview"
    bl_label = "Remove Lightmap Preview"
    bl_options = {'REGISTER', 'UNDO'}

    def execute(self, context):
        from . import materials

        objects = [obj for obj in context.selected_objects if obj.type == 'MESH']
        if not objects:
            self.report({'ERROR'}, "No mesh selected: select the objects whose lightmap preview to remove")
            return {'CANCELLED'}
        removed = sum(materials.remove_preview(obj) for obj in objects if obj.library is None)
        if removed == 0:
            self.report({'INFO'}, "No lightmap preview nodes on the selected objects")
            return {'CANCELLED'}
        self.report({'INFO'}, f"Removed {removed} preview node(s)")
        return {'FINISHED'}


class LMREFINE_OT_show_preview(bpy.types.Operator):
    """Show the lightmaps before or after refinement on every object of the scene that has a preview"""

    bl_idname = "object.lmrefine_show_preview"
    bl_label = "Show Lightmap"
    bl_options = {'REGISTER', 'UNDO'}

    shown: bpy.props.EnumProperty(
        name="Show",
        items=(('BEFORE', "Before", "The first lightmap, through the source UV map"),
               ('AFTER', "After", "The lightmap baked with the refined UV map, through the refined map")),
        default='AFTER',
    )

    def execute(self, context):
        from . import materials

        switched = [obj.name for obj in context.scene.objects
                    if obj.type == 'MESH' and obj.library is None and materials.show_preview(obj, self.shown)]
        if not switched:
            self.report({'INFO'}, "No lightmap preview to switch: run Refine Lightmap UVs with Preview on")
            return {'CANCELLED'}
        return {'FINISHED'}


def draw_menu_entry(self, context):
    """Menu entry (3D View > Object, UV Editor > UV): menus are what F3 search finds."""
    self.layout.separator()
    self.layout.operator(LMREFINE_OT_refine_uvs.bl_idname, icon='UV')


MENUS = ("VIEW3D_MT_object", "IMAGE_MT_uvs")

CLASSES = (LMREFINE_OT_refine_uvs, LMREFINE_OT_remove_preview, LMREFINE_OT_show_preview)

_register_classes, _unregister_classes = bpy.utils.register_classes_factory(CLASSES)


def register():
    _register_classes()
    for menu in MENUS:
        getattr(bpy.types, menu).append(draw_menu_entry)


def unregister():
    for menu in MENUS:
        getattr(bpy.types, menu).remove(draw_menu_entry)
    _unregister_classes()
