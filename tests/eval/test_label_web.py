"""`aeb label`'s page in headless Chromium (Debian's `chromium`), driven over the DevTools
protocol: the frame is shown with the ROI box where the ROI is, the keys label, skip and
move on, and every label is in the file before the next ROI is shown."""

import base64
import http.client
import json
import shutil
import subprocess
import threading
from pathlib import Path

import cv2
import msgspec
import numpy as np
import pytest
from websockets.sync.client import ClientConnection, connect

from aeb_radar_camera.tools.eval.labels import read_labels
from aeb_radar_camera.tools.eval.labelweb import LabelSession, make_server, pick_sample
from aeb_radar_camera.tools.eval.recording import RecordingSettings, recording_records
from aeb_radar_camera.tools.eval.scoring import Scorer, default_specs
from tests.eval.fixtures import write_sim_recording
from tests.support import wait_for

pytestmark = pytest.mark.slow

# Where the page puts the frame (label_page.py: #frame at left 8 px, top 66 px).
FRAME_LEFT, FRAME_TOP = 8, 66
DEADLINE_S = 60.0


def chromium() -> str:
    path = shutil.which("chromium") or shutil.which("chromium-browser")
    if path is None:
        pytest.fail("headless Chromium is needed: apt-get install chromium")
    return path


class DevTools:
    """A minimal DevTools client on one page target."""

    def __init__(self, ws: ClientConnection) -> None:
        self.ws = ws
        self._id = 0

    def call(self, method: str, **params: object) -> dict:
        self._id += 1
        self.ws.send(json.dumps({"id": self._id, "method": method, "params": params}))
        while True:
            msg = json.loads(self.ws.recv(timeout=DEADLINE_S))
            if msg.get("id") == self._id:
                if "error" in msg:
                    raise RuntimeError(f"{method}: {msg['error']}")
                return msg.get("result", {})

    def evaluate(self, expr: str) -> object:
        return self.call("Runtime.evaluate", expression=expr,
                         returnByValue=True)["result"].get("value")

    def key(self, key: str, code: str, vk: int) -> None:
        for kind in ("keyDown", "keyUp"):
            self.call("Input.dispatchKeyEvent", type=kind, key=key, code=code,
                      windowsVirtualKeyCode=vk, text=key if kind == "keyDown" else "")

    def screenshot(self) -> np.ndarray:
        data = base64.b64decode(self.call("Page.captureScreenshot", format="png")["data"])
        img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
        assert img is not None
        return img


@pytest.fixture
def page(tmp_path):
    rec = write_sim_recording(tmp_path / "drive.mcap", n_cycles=4)
    records = recording_records(rec.path, RecordingSettings(background_per_object=0),
                                Scorer(default_specs()), {})
    labels = tmp_path / "labels.tsv"
    items = pick_sample(records, labels, 0, [], [], (0.025,), 0)
    session = LabelSession(items, labels, "tester")
    server = make_server(session)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    profile = tmp_path / "chromium"
    proc = subprocess.Popen(
        [chromium(), "--headless=new", "--no-sandbox", "--disable-gpu",
         "--no-first-run", "--remote-debugging-port=0", "--remote-debugging-address=127.0.0.1",
         f"--user-data-dir={profile}", "--window-size=1400,800",
         "--force-device-scale-factor=1", "about:blank"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        active = profile / "DevToolsActivePort"
        wait_for(lambda: active.is_file() and active.read_text().count("\n") >= 1, DEADLINE_S,
                 0.05, "Chromium's DevTools port")
        port = int(active.read_text().split()[0])

        def page_target() -> str | None:
            conn = http.client.HTTPConnection("127.0.0.1", port, timeout=5)
            conn.request("GET", "/json/list")
            targets = json.loads(conn.getresponse().read())
            conn.close()
            return next((t["webSocketDebuggerUrl"] for t in targets if t["type"] == "page"),
                        None)

        url: str = wait_for(page_target, DEADLINE_S, 0.1, "a page target") or ""
        with connect(url, max_size=None, open_timeout=DEADLINE_S) as ws:
            tools = DevTools(ws)
            tools.call("Page.navigate", url=f"http://127.0.0.1:{server.server_address[1]}/")
            yield tools, session, labels
    finally:
        proc.terminate()
        proc.wait(timeout=30)
        server.shutdown()
        server.server_close()
        session.close()


def shown(tools: DevTools, roi_id: str) -> None:
    """Wait until the page shows `roi_id` with its frame loaded."""
    wait_for(lambda: tools.evaluate("document.body.dataset.ready") == roi_id, DEADLINE_S,
             0.05, f"the page to show {roi_id}")


def green(px: np.ndarray) -> np.ndarray:
    b, g, r = px[..., 0].astype(int), px[..., 1].astype(int), px[..., 2].astype(int)
    return (g > 200) & (r < 80) & (b < 80)


def test_the_page_draws_the_roi_on_its_frame_and_labels_with_the_keyboard(page):
    tools, session, labels = page
    first = session.state()["current"]
    shown(tools, first["id"])
    img = tools.screenshot()
    x, y, w, h = first["roi"]
    # The green box: on its top and bottom rows and its left and right columns.
    top = img[FRAME_TOP + y, FRAME_LEFT + x + 2:FRAME_LEFT + x + w - 2]
    bottom = img[FRAME_TOP + y + h - 1, FRAME_LEFT + x + 2:FRAME_LEFT + x + w - 2]
    left = img[FRAME_TOP + y + 2:FRAME_TOP + y + h - 2, FRAME_LEFT + x]
    right = img[FRAME_TOP + y + 2:FRAME_TOP + y + h - 2, FRAME_LEFT + x + w - 1]
    for edge in (top, bottom, left, right):
        assert green(edge).mean() > 0.95
    # ... and nowhere else in the frame: the rest of the rendered road is not green.
    frame = img[FRAME_TOP:FRAME_TOP + 480, FRAME_LEFT:FRAME_LEFT + 848]
    mask = np.zeros(frame.shape[:2], bool)
    mask[max(0, y - 2):y + h + 2, max(0, x - 2):x + w + 2] = True
    mask[y + 3:y + h - 3, x + 3:x + w - 3] = False
    assert green(frame[~mask]).mean() < 0.001
    # The enlarged ROI beside the frame is drawn (not the page's background).
    crop = img[FRAME_TOP:FRAME_TOP + 100, FRAME_LEFT + 848 + 16:FRAME_LEFT + 848 + 116]
    assert np.abs(crop.astype(int) - (32, 32, 32)).sum(axis=2).mean() > 20
    assert "0 of 8 labelled" in str(tools.evaluate("document.getElementById('count')"
                                                   ".textContent"))

    tools.key("y", "KeyY", 89)
    second = wait_for(lambda: (session.state()["current"] or {}).get("id") != first["id"]
                      and session.state()["current"], DEADLINE_S, 0.05, "the next ROI")
    assert read_labels(labels)[first["id"]].value == "YES"
    assert read_labels(labels)[first["id"]].who == "tester"
    shown(tools, second["id"])
    tools.key("s", "KeyS", 83)                   # skip: shown again after the others
    third = wait_for(lambda: (session.state()["current"] or {}).get("id") != second["id"]
                     and session.state()["current"], DEADLINE_S, 0.05, "the skip")
    assert session.state()["skipped"] == 1
    shown(tools, third["id"])
    tools.key("n", "KeyN", 78)
    wait_for(lambda: third["id"] in read_labels(labels), DEADLINE_S, 0.05, "the NO label")
    assert read_labels(labels)[third["id"]].value == "NO"
    assert second["id"] not in read_labels(labels)
    wait_for(lambda: "2 of 8 labelled (YES 1, NO 1" in str(tools.evaluate(
        "document.getElementById('count').textContent")), DEADLINE_S, 0.05, "the progress")
    # The new ROI on screen has its own box.
    fourth = wait_for(lambda: (session.state()["current"] or {}).get("id") != third["id"]
                      and session.state()["current"], DEADLINE_S, 0.05, "the next ROI")
    shown(tools, fourth["id"])
    x, y, w, h = fourth["roi"]
    img = tools.screenshot()
    assert green(img[FRAME_TOP + y, FRAME_LEFT + x + 2:FRAME_LEFT + x + w - 2]).mean() > 0.95


def test_label_file_survives_a_new_session(page, tmp_path):
    tools, session, labels = page
    first = session.state()["current"]
    shown(tools, first["id"])
    tools.key("a", "KeyA", 65)
    wait_for(lambda: first["id"] in read_labels(labels), DEADLINE_S, 0.05, "the label")
    assert read_labels(labels)[first["id"]].value == "ambiguous"
    resumed = LabelSession(session.items, labels, "tester")
    assert resumed.state()["labelled"] == 1
    assert resumed.state()["current"]["id"] != first["id"]
    resumed.close()
    assert Path(str(labels) + ".sample").is_file()


def click(tools: DevTools, element_id: str) -> None:
    """A real mouse click in the middle of the element, as a person clicks."""
    box = tools.evaluate(f"JSON.stringify(document.getElementById('{element_id}')"
                         ".getBoundingClientRect())")
    r = json.loads(str(box))
    x, y = r["x"] + r["width"] / 2, r["y"] + r["height"] / 2
    for kind in ("mousePressed", "mouseReleased"):
        tools.call("Input.dispatchMouseEvent", type=kind, x=x, y=y, button="left",
                   clickCount=1)


def test_buttons_beside_the_keys_say_what_yes_means_and_hide_the_answer(page):
    tools, session, labels = page
    first = session.state()["current"]
    shown(tools, first["id"])
    item = session.items[first["index"]]
    assert item.truth is not None                 # the simulator's ground truth is loaded
    text = str(tools.evaluate("document.body.innerText"))
    assert "YES: an object stands in the green box at the track's range" in text
    # the answer is not on the page: neither what the ROI was built from nor its id
    assert first["kind"] is None and first["truth_hidden"]
    info = str(tools.evaluate("document.getElementById('info').textContent")).splitlines()
    assert info[0] == f"ROI {first['index'] + 1} of 8 (ground truth loaded: its kind is not " \
                      "shown)"
    assert item.id not in text, text
    assert not item.obj_class or item.obj_class not in info[0], info
    # each answer is a button beside its key, and a click labels as the key does
    keys = [str(tools.evaluate(f"document.getElementById('{b}').textContent")).split()
            for b in ("yes", "no", "ambiguous", "skip", "back")]
    assert keys == [["Y", "yes"], ["N", "no"], ["A", "ambiguous"], ["S", "skip"],
                    ["←", "back"]]
    click(tools, "no")
    wait_for(lambda: first["id"] in read_labels(labels), DEADLINE_S, 0.05, "the click")
    assert read_labels(labels)[first["id"]].value == "NO"
    second = wait_for(lambda: (session.state()["current"] or {}).get("id") != first["id"]
                      and session.state()["current"], DEADLINE_S, 0.05, "the next ROI")
    shown(tools, second["id"])
    click(tools, "back")
    wait_for(lambda: (session.state()["current"] or {}).get("id") == first["id"],
             DEADLINE_S, 0.05, "back to the first ROI")


def test_without_ground_truth_the_kind_is_shown(tmp_path):
    rec = write_sim_recording(tmp_path / "drive.mcap", n_cycles=2)
    records = [msgspec.structs.replace(r, truth=None) for r in recording_records(
        rec.path, RecordingSettings(background_per_object=0), Scorer(default_specs()), {})]
    session = LabelSession(records, tmp_path / "labels.tsv", "t")
    current = session.state()["current"]
    assert current["kind"] == records[0].kind and not current["truth_hidden"]
    session.close()
