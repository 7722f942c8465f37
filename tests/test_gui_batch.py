"""File ▸ Batch Solve… in the window: the open rig, two short takes and a truncated one solved on a local Dask
cluster in the background (the window keeps handling events), the results table, a take opened from it in the
Mocap panel; a bad option is said in the dialog, not raised. The table sorts by a header click, shows the selected
take's preview, and shows an earlier batch's results (Open Results…, or its folder dropped on the dialog) in a later
session, whose form the dialog remembers."""
from __future__ import annotations

import json
import os
import time

import pytest
from PySide6 import QtCore, QtGui, QtWidgets

from tests.gui_helpers import drop_files, make_window, open_and_wait

pytestmark = [pytest.mark.gui, pytest.mark.data]
if not os.environ.get("CI"):
    pytest.importorskip("distributed")


def _menu_action(window, text: str):
    for menu in window.menuBar().findChildren(QtWidgets.QMenu):
        for act in menu.actions():
            if act.text().replace("&", "") == text:
                return act
    raise AssertionError(f"no menu action {text!r}")


def test_batch_solve_dialog_runs_in_the_background_and_opens_a_take(qtbot, tmp_path, ict_dir, take_dir):
    from model.take_c3d import write_c3d
    from model.takes import MarkerTake, load_take
    t = load_take(take_dir / "take.c3d")
    takes = []
    for name, pos in (("first", t.positions[:50]), ("second", t.positions[:50] + [10.0, 0.0, 0.0])):
        write_c3d(tmp_path / f"{name}.c3d", MarkerTake(pos, t.labels, t.rate, t.units))
        takes.append(str(tmp_path / f"{name}.c3d"))
    (tmp_path / "cut.c3d").write_bytes((tmp_path / "first.c3d").read_bytes()[:5000])
    takes.append(str(tmp_path / "cut.c3d"))

    w = make_window(qtbot, tmp_path, size=(1400, 1000))
    bc = w.batch
    act = _menu_action(w, "Batch Solve…")
    open_and_wait(qtbot, w, ict_dir)
    act.trigger()
    d = bc.dialog
    assert d is not None and d.isVisible() and not d.isModal()
    d.add_takes(takes)
    assert d.take_list.count() == 3
    qtbot.keyClicks(d.output_edit, str(tmp_path / "out"))
    qtbot.keyClicks(d.map_edit, str(take_dir / "marker_map.json"))
    d.workers_spin.setValue(1)

    # a bad option in "More options" is one sentence in the dialog; nothing starts
    qtbot.keyClicks(d.extra_edit, "--level nine")
    qtbot.mouseClick(d.run_button, QtCore.Qt.LeftButton)
    assert not bc.running and "--level" in d.status_label.text()
    d.extra_edit.clear()

    ticks = []
    timer = QtCore.QTimer()
    timer.timeout.connect(lambda: ticks.append(1))
    timer.start(50)
    t0 = time.perf_counter()
    with qtbot.waitSignal(bc.finished, timeout=240000) as blocker:
        qtbot.mouseClick(d.run_button, QtCore.Qt.LeftButton)
        assert bc.running and not d.run_button.isEnabled() and d.cancel_button.isEnabled()
    timer.stop()
    elapsed = time.perf_counter() - t0
    # the event loop ran all along: a 50 ms timer fired at least half as often as it could (a blocked window fires it
    # once at the end); counted against the run's own length, which a faster batch shortens
    assert len(ticks) >= max(3, 0.5 * elapsed / 0.05), f"{len(ticks)} ticks in {elapsed:.2f} s"
    rows = blocker.args[0]
    assert [r["status"] for r in rows] == ["solved", "solved", "failed"]
    assert "truncated" in rows[2]["error"]
    assert d.table.rowCount() == 3 and d.table.item(1, 1).text() == "solved"
    assert d.table.item(2, 6).text() == rows[2]["error"]
    # the RMSE's unit in its header, the explained motion as a percentage, the error sentence whole on its row
    assert d.table.horizontalHeaderItem(4).text() == "Marker RMSE\n(cm)"
    assert d.table.item(1, 5).text() == f"{100 * rows[1]['motion_explained']:.1f} %"
    error_rect = d.table.visualItemRect(d.table.item(2, 6))
    needed = d.table.fontMetrics().boundingRect(QtCore.QRect(0, 0, error_rect.width() - 8, 10000),
                                                 QtCore.Qt.TextWordWrap, rows[2]["error"])
    assert error_rect.height() >= needed.height() > d.table.rowHeight(1)
    assert d.run_button.isEnabled() and d.progress_bar.value() == 3
    summary = json.loads((tmp_path / "out" / "batch.json").read_text())
    assert [r["take"] for r in summary["takes"]] == ["first", "second", "cut"]
    assert (tmp_path / "out" / "second" / "weights.csv").exists()
    assert "solved 2" in w.statusBar().currentMessage()

    # a take opens in the Mocap panel from the table, with the batch's marker map
    d.table.selectRow(1)
    assert d.open_button.isEnabled()
    qtbot.mouseClick(d.open_button, QtCore.Qt.LeftButton)
    assert w.mocap.take is not None and w.mocap.take.n_frames == 50
    assert str(w.mocap.workspace.take_path) == takes[1]
    assert w.mocap.marker_map is not None and len(w.mocap.marker_map.labels) == 60
    assert "second" in w.mocap.panel.take_label.text()


def _click_row(qtbot, table, row: int) -> None:
    rect = table.visualItemRect(table.item(row, 1))
    qtbot.mouseClick(table.viewport(), QtCore.Qt.LeftButton, pos=rect.center())


def _click_header(qtbot, table, column: int) -> None:
    header = table.horizontalHeader()
    x = header.sectionViewportPosition(column) + header.sectionSize(column) // 2
    qtbot.mouseClick(header.viewport(), QtCore.Qt.LeftButton, pos=QtCore.QPoint(x, header.height() // 2))


def _names(table) -> list[str]:
    return [table.item(r, 0).text() for r in range(table.rowCount())]


def test_batch_results_sort_show_previews_and_open_again_in_a_later_session(qtbot, tmp_path, ict_dir, take_dir):
    from model.take_c3d import write_c3d
    from model.takes import MarkerTake, load_take
    t = load_take(take_dir / "take.c3d")
    takes = []
    for name, pos in (("first", t.positions[:40]), ("second", t.positions[40:80] + [10.0, 0.0, 0.0])):
        write_c3d(tmp_path / f"{name}.c3d", MarkerTake(pos, t.labels, t.rate, t.units))
        takes.append(str(tmp_path / f"{name}.c3d"))
    (tmp_path / "cut.c3d").write_bytes((tmp_path / "first.c3d").read_bytes()[:5000])
    takes.append(str(tmp_path / "cut.c3d"))
    map_path = str(take_dir / "marker_map.json")

    w = make_window(qtbot, tmp_path, size=(1400, 1000))
    open_and_wait(qtbot, w, ict_dir)
    _menu_action(w, "Batch Solve…").trigger()
    d = w.batch.dialog
    d.add_takes(takes)
    qtbot.keyClicks(d.output_edit, str(tmp_path / "out"))
    qtbot.keyClicks(d.map_edit, map_path)
    d.workers_spin.setValue(1)
    d.residual_combo.setCurrentText("joshi")
    with qtbot.waitSignal(w.batch.finished, timeout=240000) as blocker:
        qtbot.mouseClick(d.run_button, QtCore.Qt.LeftButton)
    rows = blocker.args[0]
    assert [r["status"] for r in rows] == ["solved", "solved", "failed"]
    assert _names(d.table) == ["first", "second", "cut"]            # the batch's order until a header is clicked
    assert d.preview_label.pixmap().isNull() and not d.open_button.isEnabled()

    # the selected take's preview: the picture the batch drew for it, scaled into the pane
    _click_row(qtbot, d.table, 1)
    drawn = QtGui.QImage(str(tmp_path / "out" / "second" / "preview.png"))
    assert drawn.size() == QtCore.QSize(480, 360)
    expected = QtGui.QPixmap.fromImage(drawn).scaled(d.preview_label.size(), QtCore.Qt.KeepAspectRatio,
                                                     QtCore.Qt.SmoothTransformation)
    assert d.preview_label.pixmap().toImage() == expected.toImage()
    assert d.preview_caption.text() == f"second: solved, frame {rows[1]['preview_frame']}"
    _click_row(qtbot, d.table, 2)
    assert d.preview_label.pixmap().isNull() and "failed" in d.preview_label.text()

    # a header click sorts; the row clicked is the take opened, however the table is sorted
    _click_header(qtbot, d.table, 0)
    assert _names(d.table) == ["cut", "first", "second"]
    _click_row(qtbot, d.table, 1)
    assert d.preview_caption.text().startswith("first: solved")
    qtbot.mouseClick(d.open_button, QtCore.Qt.LeftButton)
    assert str(w.mocap.workspace.take_path) == takes[0] and w.mocap.take.n_frames == 40
    # the marker RMSE, the worst first; a take without one (failed) last whichever way
    rmse = {r["take"]: r["marker_rmse"] for r in rows}
    _click_header(qtbot, d.table, 4)
    assert _names(d.table) == sorted(["first", "second"], key=lambda n: -rmse[n]) + ["cut"]
    _click_header(qtbot, d.table, 4)
    assert _names(d.table) == sorted(["first", "second"], key=lambda n: rmse[n]) + ["cut"]

    # a later session: the form as it was left; an earlier batch's results opened from its folder
    w2 = make_window(qtbot, tmp_path, size=(1400, 1000))
    open_and_wait(qtbot, w2, ict_dir)
    _menu_action(w2, "Batch Solve…").trigger()
    d2 = w2.batch.dialog
    assert (d2.output(), d2.map_edit.text(), d2.workers_spin.value(), d2.residual_combo.currentText()) == (
        str(tmp_path / "out"), map_path, 1, "joshi")
    assert d2.take_list.count() == 0 and d2.table.rowCount() == 0
    (tmp_path / "bad.json").write_text('{"takes": [1, 2')
    d2.results_requested.emit(str(tmp_path / "bad.json"))       # what Open Results… emits for the file chosen
    assert d2.status_label.text() == f"{tmp_path / 'bad.json'}: is not a batch summary (not JSON text)."
    assert d2.table.rowCount() == 0
    # files dropped on the dialog: takes and a folder of them join the list, a .json is the marker map, a file
    # that is none of these is one sentence; a batch's folder shows its results
    (tmp_path / "more").mkdir()
    (tmp_path / "more" / "third.c3d").write_bytes((tmp_path / "first.c3d").read_bytes())
    d2.map_edit.clear()
    assert drop_files(d2, [tmp_path / "first.c3d", tmp_path / "more", take_dir / "marker_map.json"])
    assert d2.takes() == [takes[0], str(tmp_path / "more")] and d2.map_edit.text() == map_path
    (tmp_path / "face.obj").write_text("v 0 0 0\n")
    assert drop_files(d2, [tmp_path / "face.obj"])
    assert d2.status_label.text().startswith(f"{tmp_path / 'face.obj'}: is not a take") and d2.take_list.count() == 2
    assert drop_files(d2, [tmp_path / "out"])
    assert _names(d2.table) == ["first", "second", "cut"]
    assert d2.table.item(2, 6).text() == rows[2]["error"]
    assert d2.table.horizontalHeaderItem(4).text() == "Marker RMSE\n(cm)"
    assert "solved 2, skipped 0 (complete), failed 1" in d2.status_label.text()
    _click_row(qtbot, d2.table, 1)
    assert d2.preview_label.pixmap().toImage() == expected.toImage()
    second = d2.table.visualItemRect(d2.table.item(1, 1)).center()
    qtbot.mouseDClick(d2.table.viewport(), QtCore.Qt.LeftButton, pos=second)
    assert str(w2.mocap.workspace.take_path) == takes[1] and w2.mocap.take.n_frames == 40
    assert w2.mocap.marker_map is not None and w2.mocap.marker_map.source == map_path
    _click_row(qtbot, d2.table, 0)                                   # Enter on a row opens it too
    qtbot.keyClick(d2.table, QtCore.Qt.Key_Return)
    assert str(w2.mocap.workspace.take_path) == takes[0]


def test_batch_solve_refuses_an_output_folder_where_it_would_write_over_what_it_reads(qtbot, tmp_path):
    """The output folder was checked only as a folder: a take given in it is left out of the solve, but a file of
    another take's set could be it (an earlier batch's weights.csv, written over by take01's), or the take the
    Mocap panel has open; its summary could land among a folder of takes given (read as one more take by the next
    batch). Each is one sentence in the dialog, nothing starts, every file as it was."""
    w = make_window(qtbot, tmp_path)
    name = w.document.rig.shape_names[0]
    out, day1 = tmp_path / "out", tmp_path / "day1"
    (out / "take01").mkdir(parents=True)
    earlier = out / "take01" / "weights.csv"
    earlier.write_text(f"frame,{name}\n0,0.25\n1,0.75\n")
    take = tmp_path / "take01.csv"
    take.write_text(f"frame,{name}\n0,0.5\n1,1\n")
    day1.mkdir()
    (day1 / "a.csv").write_text(f"frame,{name}\n0,1\n")
    bc = w.batch
    d = bc.show_dialog()
    before = {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file() and "settings" not in p.parts}
    fix = "choose another output folder."
    for takes, folder, open_take, sentence in (
            ([earlier, take], out, None, f"{earlier}: is a take to solve itself, which this batch reads; {fix}"),
            ([day1, take], day1, None, f"{day1 / 'batch.csv'}: is in {day1}, a folder of takes to solve, and would "
                                       f"be read there as one more take; {fix}"),
            ([take], out, earlier, f"{earlier}: is the take itself, which the window has open; {fix}")):
        if open_take is not None:
            assert w.mocap.load_take(open_take)
        d.take_list.clear()
        d.add_takes([str(t) for t in takes])
        d.output_edit.setText(str(folder))
        qtbot.mouseClick(d.run_button, QtCore.Qt.LeftButton)
        assert not bc.running and d.status_label.text() == sentence, d.status_label.text()
    assert {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file() and "settings" not in p.parts} == before
    assert not (out / "batch.json").exists() and not (day1 / "batch.json").exists()


def test_batch_solve_solves_a_take_added_from_its_output_folder(qtbot, tmp_path):
    """A take added to the dialog from inside the output folder was left out of the solve without a word. It is
    solved; an earlier batch's output added as a take is left out, and the dialog says so in one sentence."""
    w = make_window(qtbot, tmp_path)
    name = w.document.rig.shape_names[0]
    out = tmp_path / "out"
    (out / "old").mkdir(parents=True)
    inside, earlier = out / "take01.csv", out / "old" / "weights.csv"
    for p in (inside, earlier):
        p.write_text(f"frame,time,{name}\n0,0,0.5\n1,0.033,1\n")
    bc = w.batch
    d = bc.show_dialog()
    d.take_list.clear()
    d.add_takes([str(inside), str(earlier)])
    d.output_edit.setText(str(out))
    d.workers_spin.setValue(1)
    sentence = (f"{earlier}: is a batch's own output in the output folder {out}, not a take to solve; left out (copy "
                "it elsewhere to solve it).")
    with qtbot.waitSignal(bc.finished, timeout=240000) as blocker:
        qtbot.mouseClick(d.run_button, QtCore.Qt.LeftButton)
        assert bc.running and d.status_label.text().endswith(sentence), d.status_label.text()
    assert [(r["take"], r["status"]) for r in blocker.args[0]] == [("take01", "solved")]
    assert d.status_label.text() == (f"Batch: solved 1, skipped 0 (complete), failed 0; summary in "
                                     f"{out / 'batch.json'}. {sentence}")
    assert (out / "take01" / "weights.csv").is_file()
