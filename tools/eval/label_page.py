"""The label tool's page (served by tools/eval/labelweb.py): the frame with the ROI in
green on the left, the ROI enlarged on the right, what is known about it below, a line
saying what YES and NO mean, and the answers as buttons beside their keys: Y yes, N no,
A ambiguous, S (or space) skip, left arrow back. A ROI whose ground truth is loaded is
shown without what it was built from (its kind, class and id would give the answer
away)."""

PAGE = """<!doctype html>
<html><head><meta charset="utf-8"><title>aeb label</title>
<style>
 body { margin: 0; font: 14px sans-serif; background: #202020; color: #e8e8e8; }
 #bar { position: absolute; left: 0; top: 0; height: 40px; width: 100%;
        background: #303030; line-height: 40px; padding-left: 8px; box-sizing: border-box; }
 #progress { display: inline-block; width: 240px; height: 10px; background: #555;
             vertical-align: middle; margin-left: 12px; }
 #progress div { height: 10px; background: #3c9; width: 0; }
 #frame { position: absolute; left: 8px; top: 66px; image-rendering: pixelated; }
 #crop { position: absolute; top: 66px; image-rendering: pixelated; }
 #info { position: absolute; left: 8px; white-space: pre; }
 #keys { display: inline-block; margin-left: 12px; }
 #keys button { font: 14px sans-serif; margin-right: 4px; padding: 3px 10px;
                background: #444; color: #f0f0f0; border: 1px solid #777;
                border-radius: 3px; cursor: pointer; }
 #keys button:hover { background: #555; }
 #keys kbd { font-weight: bold; color: #ffd75e; }
 #meaning { position: absolute; left: 8px; top: 40px; height: 22px; line-height: 22px;
            color: #ddd; }
 .done { color: #3c9; font-size: 20px; }
</style></head>
<body>
<div id="bar"><span id="count">loading</span><span id="progress"><div></div></span>
 <span id="keys"><button id="yes"><kbd>Y</kbd> yes</button><button id="no"><kbd>N</kbd>
 no</button><button id="ambiguous"><kbd>A</kbd> ambiguous</button><button id="skip">
 <kbd>S</kbd> skip</button><button id="back"><kbd>&larr;</kbd> back</button></span></div>
<div id="meaning"><b>YES</b>: an object stands in the green box at the track's range,
 something the car must not hit. <b>NO</b>: nothing does (road, a flat patch, something
 overhead, an empty box). <b>A</b>: cannot tell.</div>
<img id="frame" alt=""><img id="crop" alt="">
<div id="info"></div>
<script>
let state = null;
async function load(url, body) {
  const opts = body ? {method: "POST", headers: {"Content-Type": "application/json"},
                       body: JSON.stringify(body)} : {};
  const r = await fetch(url, opts);
  state = await r.json();
  show();
}
function show() {
  const s = state;
  document.getElementById("count").textContent =
    `${s.labelled} of ${s.total} labelled (YES ${s.yes}, NO ${s.no}, ambiguous ` +
    `${s.ambiguous}), ${s.skipped} skipped - ${s.who}`;
  document.querySelector("#progress div").style.width =
    (s.total ? 240 * s.labelled / s.total : 0) + "px";
  const frame = document.getElementById("frame"), crop = document.getElementById("crop");
  const info = document.getElementById("info");
  if (s.current === null) {
    frame.removeAttribute("src"); crop.removeAttribute("src");
    info.style.top = "74px";
    info.innerHTML = '<span class="done">All ROIs of this sample are labelled.</span>';
    document.body.dataset.ready = "done";
    return;
  }
  const c = s.current;
  frame.onload = () => {
    crop.style.left = (16 + frame.naturalWidth) + "px";
    info.style.top = (74 + frame.naturalHeight) + "px";
    document.body.dataset.ready = c.id;
  };
  document.body.dataset.ready = "";
  frame.src = `/frame/${c.index}.png`;
  crop.src = `/crop/${c.index}.png`;
  const what = c.truth_hidden
    ? `ROI ${c.index + 1} of ${s.total} (ground truth loaded: its kind is not shown)\\n`
    : `${c.id}\\n${c.kind} ${c.obj_class} | `;
  info.textContent =
    `${what}range ${c.range_m.toFixed(1)} m | ` +
    `TTC ${c.ttc_s === null ? "-" : c.ttc_s.toFixed(1) + " s"} | track ${c.track_id}\\n` +
    `edge density ${c.density.toFixed(3)} | lighting ${c.lighting} | camera ${c.camera}` +
    (c.label ? `\\nlabelled ${c.label}` : "");
}
function act(what) {
  if (!state || state.current === null) return false;
  const id = state.current.id;
  if (what === "yes") load("/api/label", {id: id, value: "YES"});
  else if (what === "no") load("/api/label", {id: id, value: "NO"});
  else if (what === "ambiguous") load("/api/label", {id: id, value: "ambiguous"});
  else if (what === "skip") load("/api/skip", {id: id});
  else if (what === "back") load("/api/back", {id: id});
  else return false;
  return true;
}
const KEYS = {y: "yes", n: "no", a: "ambiguous", s: "skip", " ": "skip",
              arrowleft: "back"};
document.addEventListener("keydown", (e) => {
  if (act(KEYS[e.key.toLowerCase()])) e.preventDefault();
});
for (const what of ["yes", "no", "ambiguous", "skip", "back"]) {
  const b = document.getElementById(what);
  b.addEventListener("click", () => { act(what); b.blur(); });
}
load("/api/state");
</script></body></html>
"""
