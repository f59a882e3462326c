"""The label tool's page (served by tools/eval/labelweb.py): the frame with the ROI in
green on the left, the ROI enlarged on the right, what is known about it below, and the
keys: Y yes, N no, A ambiguous, S (or space) skip, left arrow back."""

PAGE = """<!doctype html>
<html><head><meta charset="utf-8"><title>aeb label</title>
<style>
 body { margin: 0; font: 14px sans-serif; background: #202020; color: #e8e8e8; }
 #bar { position: absolute; left: 0; top: 0; height: 40px; width: 100%;
        background: #303030; line-height: 40px; padding-left: 8px; box-sizing: border-box; }
 #progress { display: inline-block; width: 240px; height: 10px; background: #555;
             vertical-align: middle; margin-left: 12px; }
 #progress div { height: 10px; background: #3c9; width: 0; }
 #frame { position: absolute; left: 8px; top: 48px; image-rendering: pixelated; }
 #crop { position: absolute; top: 48px; image-rendering: pixelated; }
 #info { position: absolute; left: 8px; white-space: pre; }
 #keys { color: #aaa; }
 .done { color: #3c9; font-size: 20px; }
</style></head>
<body>
<div id="bar"><span id="count">loading</span><span id="progress"><div></div></span>
 <span id="keys">&nbsp; Y yes &middot; N no &middot; A ambiguous &middot; S skip
 &middot; &larr; back</span></div>
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
    info.style.top = "56px";
    info.innerHTML = '<span class="done">All ROIs of this sample are labelled.</span>';
    document.body.dataset.ready = "done";
    return;
  }
  const c = s.current;
  frame.onload = () => {
    crop.style.left = (16 + frame.naturalWidth) + "px";
    info.style.top = (56 + frame.naturalHeight) + "px";
    document.body.dataset.ready = c.id;
  };
  document.body.dataset.ready = "";
  frame.src = `/frame/${c.index}.png`;
  crop.src = `/crop/${c.index}.png`;
  info.textContent =
    `${c.id}\\n${c.kind} ${c.obj_class} | range ${c.range_m.toFixed(1)} m | ` +
    `TTC ${c.ttc_s === null ? "-" : c.ttc_s.toFixed(1) + " s"} | track ${c.track_id}\\n` +
    `edge density ${c.density.toFixed(3)} | lighting ${c.lighting} | camera ${c.camera}` +
    (c.label ? `\\nlabelled ${c.label}` : "");
}
document.addEventListener("keydown", (e) => {
  if (!state || state.current === null) return;
  const id = state.current.id;
  const k = e.key.toLowerCase();
  if (k === "y") load("/api/label", {id: id, value: "YES"});
  else if (k === "n") load("/api/label", {id: id, value: "NO"});
  else if (k === "a") load("/api/label", {id: id, value: "ambiguous"});
  else if (k === "s" || k === " ") load("/api/skip", {id: id});
  else if (e.key === "ArrowLeft") load("/api/back", {id: id});
  else return;
  e.preventDefault();
});
load("/api/state");
</script></body></html>
"""
