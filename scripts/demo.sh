#!/usr/bin/env bash
# The demo on the bundled example data: build the FMUs and the twin CLI, calibrate the twin on
# dataset1, compare it with the three records (dataset3 has contact the twin does not know
# about), train the GP corrector, run active learning over the three records in every query
# mode, then diagnose dataset3, add the physics the diagnosis names and compare again (and, on
# synthetic records, two changes at once, a force outside the library, discovered, and a
# building measured by velocity sensors in mm/s), run the
# simulated real-time hybrid test (the contact threshold, the law learned from it), stream
# dataset3 through `twin watch` (its failing window diagnosed in the background; with the GP
# corrector, its latent variance flagging the change and the corrector learning online; a
# synthetic stream with two changes in a row, each located, diagnosed after it and its
# recalibrated twin adopted; on a live page in a headless browser, photographed to
# out/demo/page.png), run
# the resulting twin with `twin run` as any SSP system, and control the structure with LQR
# designs on the twin (attenuation, contacts, retuning and gain scheduling, a controlled record
# predicted in the closed loop), and end from Python: the shear_twin package on dataset3 and a
# fleet of synthetic structures on Dask. It makes what it needs first: the Python environment
# (.venv), the FMUs and the CLI, the shear_twin package. Reports, predictions and plots go to
# out/demo/.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"

# Every section starts with the time since the demo began, so a newcomer sees how far along it
# is; the set-up steps below show pip's and cargo's own progress (SHEAR_TWIN_PROGRESS).
demo_start=$SECONDS
section() {
  local t=$((SECONDS - demo_start))
  printf '[%2d:%02d] %s\n' $((t / 60)) $((t % 60)) "$*"
}
export SHEAR_TWIN_PROGRESS=1
trap 'status=$?; [ "$status" -eq 0 ] || section "the demo stopped (exit $status) at the section above"' EXIT

# What the demo needs from the machine, first: the Debian packages (chromium and its driver, for
# the live page's screenshot) installed as root with apt-get, or a stop at once naming them —
# never a failure at the end. Then the Python environment (.venv with the pinned packages; quick
# when it is up to date), the FMUs and the CLI, then the shear_twin package built from python/
# into .venv: the Python part and the fleet at the end need it, and a package built from older
# sources would not be this checkout's.
section "== set-up 1/4: the machine's packages (scripts/prerequisites.sh --demo) =="
scripts/prerequisites.sh --demo
section "== set-up 2/4: the Python environment .venv (scripts/setup-python.sh; pip's progress below) =="
scripts/setup-python.sh
section "== set-up 3/4: the FMUs and the twin CLI (scripts/build-fmus.sh: cargo, release; minutes the first time) =="
scripts/build-fmus.sh
section "== set-up 4/4: the shear_twin package into .venv (maturin, release; minutes the first time) =="
scripts/install-python-package.sh
twin=target/release/twin
out=out/demo
mkdir -p "$out"

section "== twin calibrate on dataset1 (MAP, priors of the reference paper) =="
"$twin" calibrate --data data/dataset1.csv --out "$out/calibrated.ssp" \
  --validate data/dataset2.csv data/dataset3.csv \
  --report "$out/calibrate-dataset1.json" --plot "$out/calibrate-dataset1.svg"

echo
section "== long records: two 4-minute runs (12,288 samples each) of a roving accelerometer, floor 1 then floor 3 =="
echo "-- the starts are screened on each run's first 2,048 samples, the best refined on every sample --"
"$twin" synth --seed 11 --duration 240 --channels acc1 --out "$out/roving-floor1.csv" >/dev/null
"$twin" synth --seed 12 --duration 240 --channels acc3 --out "$out/roving-floor3.csv" >/dev/null
"$twin" calibrate --data "$out/roving-floor1.csv" "$out/roving-floor3.csv" --out "$out/roving.ssp" \
  --report "$out/calibrate-roving.json" > "$out/calibrate-roving.txt"
head -4 "$out/calibrate-roving.txt"
echo "-- a third run on floor 2, and the three runs' modes merged through the measured force: every floor's shape --"
"$twin" synth --seed 13 --duration 240 --channels acc2 --out "$out/roving-floor2.csv" >/dev/null
"$twin" modal --data "$out/roving-floor1.csv" --data "$out/roving-floor2.csv" \
  --data "$out/roving-floor3.csv" --report "$out/modal-roving.json" > "$out/modal-roving.txt"
head -5 "$out/modal-roving.txt"

for n in 1 2 3; do
  echo
  section "== twin compare on dataset$n =="
  "$twin" compare --twin "$out/calibrated.ssp" --data "data/dataset$n.csv" \
    --report "$out/compare-dataset$n.json" --predictions "$out/predictions-dataset$n.csv" \
    --plot "$out/compare-dataset$n.svg" --frf --modes
done

echo
section "== twin modal: the calibrated twin's natural frequencies, damping and shapes with their posterior sd"
echo "   (checked by sampling the posterior), beside the modes identified from dataset2 (LSCF, SSI-COV) =="
"$twin" modal --twin "$out/calibrated.ssp" --data data/dataset2.csv --report "$out/modal-dataset2.json" \
  --plot "$out/modal-dataset2.svg"

echo
section "== twin train: the GP bias corrector on dataset1, behind the calibrated physics =="
"$twin" train --twin "$out/calibrated.ssp" --data data/dataset1.csv --out "$out/corrected.ssp" \
  --stride 2 --report "$out/train-dataset1.json"
for n in 2 3; do
  echo
  section "== twin compare with the corrector on dataset$n (latent variance in the predictions CSV) =="
  "$twin" compare --twin "$out/corrected.ssp" --data "data/dataset$n.csv" \
    --report "$out/compare-corrected-dataset$n.json" \
    --predictions "$out/predictions-corrected-dataset$n.csv" --plot "$out/compare-corrected-dataset$n.svg"
done

echo
section "== twin learn: active learning (Algorithm 1) over datasets 1-3, every query mode (Table 2) =="
echo "   (the reference paper's form: GPs of the measured accelerations)"
"$twin" learn --twin "$out/calibrated.ssp" --data data/dataset1.csv data/dataset2.csv \
  data/dataset3.csv --modes all --target measured --out-dir "$out/learn"

echo
section "== twin diagnose on dataset3: which action, which effect, where, how strong =="
"$twin" diagnose --twin "$out/calibrated.ssp" --data data/dataset3.csv \
  --report "$out/diagnose-dataset3.json" --plot "$out/diagnose-dataset3.svg"

echo
section "== twin add-physics: switch the diagnosed effect on, estimate it on dataset3, then refit it with"
echo "   the structure over dataset3 and the twin's own records (datasets 1-3: a multi-record MAP) =="
"$twin" add-physics --twin "$out/calibrated.ssp" --diagnosis "$out/diagnose-dataset3.json" \
  --data data/dataset3.csv --out "$out/with-contact.ssp" --report "$out/add-physics-dataset3.json"

for n in 1 2 3; do
  echo
  section "== twin compare with the added physics on dataset$n =="
  "$twin" compare --twin "$out/with-contact.ssp" --data "data/dataset$n.csv" \
    --report "$out/compare-with-contact-dataset$n.json" --plot "$out/compare-with-contact-dataset$n.svg"
done

echo
section "== twin run: the twin with the added physics is an SSP system any FMI master runs; run it as one =="
cut -d, -f1,2 data/dataset3.csv >"$out/force-dataset3.csv"
"$twin" run "$out/with-contact.ssp" --input "$out/force-dataset3.csv" --stop 19.98046875 --step 0.01953125 \
  --output "$out/run-with-contact-dataset3.csv" --plot "$out/run-with-contact-dataset3.svg"

echo
section "== a faulty sensor is not physics: dataset2 with floor 2's accelerometer reading 0.8 of the truth =="
awk -F, 'NR == 1 { print; next } { printf "%s,%s,%s,%.9g,%s\n", $1, $2, $3, $4 * 0.8, $5 }' \
  data/dataset2.csv >"$out/dataset2-sensor2-gain0.8.csv"
"$twin" diagnose --twin "$out/calibrated.ssp" --data "$out/dataset2-sensor2-gain0.8.csv" \
  --report "$out/diagnose-sensor-fault.json"

echo
section "== several changes at once, and a force outside the library: records of twin synth's structure =="
"$twin" synth --seed 1 --noise-sd 0.003 --out "$out/synth-unchanged.csv" >/dev/null
"$twin" calibrate --data "$out/synth-unchanged.csv" --out "$out/synth-calibrated.ssp" >/dev/null
echo "-- storey 2 lost 15 % of its stiffness and floors 2 and 3 touch: forward selection --"
"$twin" synth --seed 2 --noise-sd 0.003 --force-window 12:17:3:0.5 --change k2@0:0.85 \
  --effect contact@2-3:gap=5e-4,stiffness=9000,side=both \
  --out "$out/synth-two-changes.csv" --truth "$out/synth-two-changes-truth.json" >/dev/null
"$twin" diagnose --twin "$out/synth-calibrated.ssp" --data "$out/synth-two-changes.csv" \
  --report "$out/diagnose-two-changes.json"
echo "-- velocity-squared damping in storey 2, which the FMU's library lacks: discovered --"
"$twin" synth --seed 2 --noise-sd 0.003 --force-window 12:17:3:0.5 \
  --effect quadratic-damping@2:coefficient=2000 \
  --out "$out/synth-quadratic-damping.csv" --truth "$out/synth-quadratic-damping-truth.json" >/dev/null
"$twin" diagnose --twin "$out/synth-calibrated.ssp" --data "$out/synth-quadratic-damping.csv" \
  --report "$out/diagnose-quadratic-damping.json" --plot "$out/diagnose-quadratic-damping.svg"
"$twin" add-physics --twin "$out/synth-calibrated.ssp" --diagnosis "$out/diagnose-quadratic-damping.json" \
  --data "$out/synth-quadratic-damping.csv" --out "$out/with-discovered.ssp"
"$twin" compare --twin "$out/with-discovered.ssp" --data "$out/synth-quadratic-damping.csv" \
  --report "$out/compare-with-discovered.json"
echo "-- velocity sensors in mm/s instead of accelerometers (geophones): the twin calibrated on them, --"
echo "   and a cubic stiffness in storey 1 diagnosed with every channel in its own quantity --"
"$twin" synth --seed 1 --noise-fraction 0.03 --channels vel1,vel2,vel3 --units vel=mm/s \
  --out "$out/synth-velocities.csv" >/dev/null
"$twin" calibrate --data "$out/synth-velocities.csv" --out "$out/synth-velocities.ssp" >/dev/null
"$twin" synth --seed 2 --noise-fraction 0.03 --channels vel1,vel2,vel3 --units vel=mm/s \
  --force-window 12:17:3:0.5 --effect cubic@1:stiffness=2e9 \
  --out "$out/synth-velocities-cubic.csv" --truth "$out/synth-velocities-cubic-truth.json" >/dev/null
"$twin" diagnose --twin "$out/synth-velocities.ssp" --data "$out/synth-velocities-cubic.csv" \
  --report "$out/diagnose-velocities.json"

echo
section "== another building: five storeys shaken at the base, accelerometers on floors 1, 3 and 5 reading in g =="
echo "-- the twin from the drawings (data/five-storey/nominal.json), calibrated on a small shake of the building --"
b5="$out/five-storey"
mkdir -p "$b5"
"$twin" init --storeys 5 --excitation base --nominal data/five-storey/nominal.json --out "$b5/drawings.ssp"
# The building as it is, with a cubic stiffness in storey 3 nobody told the twin about: a small
# shake (ground acceleration RMS 0.013 m/s2) hardly shows it, a strong one (0.18 m/s2) does.
five_storey_synth() {
  "$twin" synth --storeys 5 --excitation base --mass 5.2,5.0,4.8,4.6,4.4 --damping 3,2.5,2.5,2,2 \
    --stiffness 5200,4800,4400,4000,3600 --effect cubic@3:stiffness=1e7 \
    --channels acc1,acc3,acc5 --units acc=g --duration 20 "$@"
}
five_storey_synth --seed 1 --force-rms 0.02 --out "$b5/small-shake.csv" --truth "$b5/small-shake-truth.json" >/dev/null
five_storey_synth --seed 3 --force-rms 0.02 --out "$b5/small-shake-2.csv" --truth "$b5/small-shake-2-truth.json" >/dev/null
five_storey_synth --seed 2 --out "$b5/strong-shake.csv" --truth "$b5/strong-shake-truth.json" >/dev/null
head -2 "$b5/strong-shake.csv"
"$twin" calibrate --twin "$b5/drawings.ssp" --data "$b5/small-shake.csv" --out "$b5/calibrated.ssp" \
  --report "$b5/calibrate.json" --starts 4
echo "-- another small shake: the twin agrees, and the diagnosis is none --"
"$twin" diagnose --twin "$b5/calibrated.ssp" --data "$b5/small-shake-2.csv" --report "$b5/diagnose-small-shake-2.json"
echo "-- a strong shake shows what the twin was not told about: compare fails, the diagnosis names it --"
"$twin" compare --twin "$b5/calibrated.ssp" --data "$b5/strong-shake.csv" --report "$b5/compare-strong-shake.json" \
  --plot "$b5/compare-strong-shake.svg"
"$twin" diagnose --twin "$b5/calibrated.ssp" --data "$b5/strong-shake.csv" --report "$b5/diagnose-strong-shake.json" \
  --plot "$b5/diagnose-strong-shake.svg"
"$twin" add-physics --twin "$b5/calibrated.ssp" --diagnosis "$b5/diagnose-strong-shake.json" \
  --data "$b5/strong-shake.csv" --out "$b5/with-cubic.ssp" --report "$b5/add-physics.json"
echo "-- and compare passes with it --"
"$twin" compare --twin "$b5/with-cubic.ssp" --data "$b5/strong-shake.csv" --report "$b5/compare-with-cubic.json" \
  --plot "$b5/compare-with-cubic.svg"

echo "-- frequency tracking in operation: five minutes of the building (the twin's nominal) under ground"
echo "   motion, storey 2 15 % softer from 150 s, watched with the modes identified on a sliding minute --"
echo '{"ground_motion": {"strong_end": 100000}}' > "$b5/stationary.json"
"$twin" init --storeys 5 --excitation base --nominal data/five-storey/nominal.json --out "$b5/nominal.ssp"
"$twin" synth --scenario "$b5/stationary.json" --storeys 5 --excitation base --nominal data/five-storey/nominal.json \
  --channels acc1,acc3,acc5 --units acc=g --duration 300 --seed 4 --change k2@150:0.85 --out "$b5/softer-storey.csv" >/dev/null
"$twin" watch --no-diagnosis --track-modes --twin "$b5/nominal.ssp" --source "$b5/softer-storey.csv" \
  --alerts "$b5/softer-storey-alerts.jsonl" --modes-plot "$b5/softer-storey-frequencies.svg" >/dev/null
grep -m 2 '"kind":"frequency"' "$b5/softer-storey-alerts.jsonl"
"$twin" modal --twin "$b5/nominal.ssp" --plot "$b5/modes.svg" --samples 0 > "$b5/modes.txt"
head -3 "$b5/modes.txt"
echo "-- an ambient record (the responses alone, as a building's monitoring measures them: no ground_acc"
echo "   column) of the building with storey 2 15 % softer: diagnosed by its modes --"
"$twin" synth --scenario "$b5/stationary.json" --storeys 5 --excitation base --nominal data/five-storey/nominal.json \
  --channels acc1,acc3,acc5 --units acc=g --duration 120 --seed 5 --change k2@0:0.85 --out "$b5/softer-measured.csv" >/dev/null
cut -d, -f1,3- "$b5/softer-measured.csv" > "$b5/softer-ambient.csv"
head -1 "$b5/softer-ambient.csv"
"$twin" diagnose --twin "$b5/nominal.ssp" --data "$b5/softer-ambient.csv" --report "$b5/diagnose-ambient.json" \
  --plot "$b5/diagnose-ambient.svg"

echo
section "== the simulated real-time hybrid test (paper section 5): where contact starts, and the contact law learned from it =="
echo "-- cut as the paper cuts it (the specimen is floors 2 and 3), then with floor 2 numerical --"
"$twin" hybrid threshold --twin "$out/calibrated.ssp" \
  --report "$out/hybrid-threshold.json" --plot "$out/hybrid-threshold.svg"
"$twin" hybrid threshold --twin "$out/calibrated.ssp" --split specimen-floor-3 \
  --report "$out/hybrid-threshold-specimen-floor-3.json"
"$twin" hybrid run --twin "$out/calibrated.ssp" --peak 5 --a-err 0 --a-err 0.05 \
  --report "$out/hybrid-run.json" --plot "$out/hybrid-run.svg"
echo "-- an actuator 5 control steps late, then with third-order delay compensation (floor 2 numerical:"
echo "   with floor 2 in the specimen a delay makes the interface a neutral loop, refused) --"
"$twin" hybrid run --twin "$out/calibrated.ssp" --split specimen-floor-3 --peak 5 --a-err 0 \
  --delay 0.0048828125 --report "$out/hybrid-delay.json"
"$twin" hybrid run --twin "$out/calibrated.ssp" --split specimen-floor-3 --peak 5 --a-err 0 \
  --delay 0.0048828125 --compensate 3 --report "$out/hybrid-delay-compensated.json"
echo "-- the law the hybrid test learned, added to the twin (held), the structure refitted over its records, on datasets 1-3 --"
"$twin" add-physics --twin "$out/calibrated.ssp" --hybrid "$out/hybrid-run.json" --out "$out/with-hybrid-contact.ssp" \
  --report "$out/add-physics-hybrid.json"
for n in 1 2 3; do
  "$twin" compare --twin "$out/with-hybrid-contact.ssp" --data "data/dataset$n.csv" \
    --report "$out/compare-with-hybrid-contact-dataset$n.json"
done

echo
section "== twin watch: dataset3 streamed through the twin calibrated on dataset1, sample by sample;"
echo "   the failing window is diagnosed in the background =="
rm -f "$out"/watch-dataset3*  # a fresh stream, not a resume
"$twin" watch --twin "$out/calibrated.ssp" --source - --alerts "$out/watch-dataset3.jsonl" \
  --checkpoint "$out/watch-dataset3-checkpoint.json" <data/dataset3.csv
echo
section "== twin watch: the same stream through the twin with the GP corrector, which queries and"
echo "   learns online (its budget: 256 points) and says where it is unsure =="
"$twin" watch --no-diagnosis --twin "$out/corrected.ssp" --source data/dataset3.csv \
  --alerts "$out/watch-corrected-dataset3.jsonl" 
python3 - "$out/watch-dataset3.jsonl" "$out/watch-corrected-dataset3.jsonl" <<'PY'
import json, sys
for path in sys.argv[1:]:
    print(f"  {path}:")
    for line in open(path):
        a = json.loads(line)
        if a["kind"] in ("failing", "recovered", "uncertain", "certain", "gap", "bad_sample"):
            floors = a.get("floors", "")
            change = a.get("change")
            located = f" (changed at {change['time']:.2f} s, {change['low']:.2f}-{change['high']:.2f})" if change else ""
            print(f"    alert at {a['time']:7.3f} s: {a['kind']} {floors}{located}")
        elif a["kind"] == "diagnosis":
            effects = ", ".join(
                e["label"] + " (" + ", ".join(f"{k} {v:.4g}" for k, v in e["parameters"].items()) + ")"
                for e in a.get("effects", []))
            before = max(a["nmse_before"]); after = max(a["nmse_after"])
            print(f"    alert at {a['time']:7.3f} s: diagnosis of the window from {a['window_start']:.3f} s"
                  f" (run on {a['from']:.2f}-{a['to']:.2f} s, {a['samples_used']} samples, {a['seconds']:.1f} s in the background):"
                  f" {a['action']} {effects}; worst-floor NMSE {before:.2f} % -> {after:.3f} %")
        elif a["kind"] == "end" and a.get("still_failing"):
            for w in a["still_failing"]:
                print(f"    end at {a['time']:7.3f} s: still failing since {w['start']:.3f} s {w['floors']} (no recovery)")
        if a["kind"] == "end" and a.get("learning"):
            l = a["learning"]
            print(f"    corrector: {l['queries']} queries learned, {l['training_points']} training points;"
                  f" worst-floor NMSE over the stream {max(a['nmse']):.2f} %")
PY

echo
section "== the operational twin meets changes: a 65 s stream of twin synth's structure, storey 2 15 % softer"
echo "   from 17.3 s, floor 3 20 % heavier from 40.1 s, replayed at full speed (--diagnosis-wait) with"
echo "   --adopt: each change located, diagnosed on what came after it from the state the twin reached"
echo "   there, and once a look's verdict is firm (by its own evidence, or two looks agreeing) the"
echo "   recalibrated twin adopted without losing a sample =="
"$twin" synth --seed 5 --noise-sd 0.003 --duration 65 --change k2@17.3:0.85 --change m3@40.1:1.2 \
  --out "$out/stream-two-changes.csv" >/dev/null
rm -f "$out"/watch-two-changes*  # a fresh stream, not a resume
"$twin" watch --twin "$out/synth-calibrated.ssp" --source "$out/stream-two-changes.csv" \
  --alerts "$out/watch-two-changes.jsonl" --checkpoint "$out/watch-two-changes-checkpoint.json" \
  --diagnosis-wait --adopt
python3 - "$out/watch-two-changes.jsonl" <<'PY'
import json, sys
for line in open(sys.argv[1]):
    a = json.loads(line)
    if a["kind"] == "failing":
        c = a["change"]
        print(f"  {a['time']:6.2f} s  failing: the change located at {c['time']:.2f} s ({c['low']:.2f}-{c['high']:.2f})")
    elif a["kind"] == "diagnosis":
        print(f"  {a['time']:6.2f} s  diagnosis look {a['round']}, fitted from {a['fitted_from']:.2f} s"
              f" ({a['post_change_seconds']:.0f} s after it): {a['action']}, worst-floor NMSE"
              f" {max(a['nmse_before']):.1f} % -> {max(a['nmse_after']):.3f} %{', firm' if a['firm'] else ''}")
        if a.get("waited"):
            print(f"           waited {a['waited']}")
    elif a["kind"] == "adopted":
        moved = ", ".join(f"{p['name']} = {p['value']:.4g}" for p in a["parameters"][:1])
        print(f"  {a['time']:6.2f} s  adopted {a['twin']} ({a['verdict']}: {moved})")
    elif a["kind"] == "end":
        print(f"  {a['time']:6.2f} s  end: {len(a['still_failing'])} window(s) still failing,"
              f" NMSE over the last window {' / '.join(f'{x:.2f}' for x in a['rolling_nmse'])} %")
PY

echo
section "== the watch on a screen: dataset3 replayed at 2× real time into twin watch --serve, the page opened"
echo "   in a headless chromium and photographed once the background diagnosis has landed on it =="
echo "   to watch it in your browser (then open the URL it prints):"
echo "   python3 scripts/replay.py data/dataset3.csv --speed 0.5 | $twin watch --twin $out/calibrated.ssp \\"
echo "     --source - --alerts $out/page-alerts.jsonl --serve 127.0.0.1:8080 --serve-linger 600"
.venv/bin/python scripts/page_demo.py --twin-bin "$twin" --twin "$out/calibrated.ssp" \
  --record data/dataset3.csv --alerts "$out/page-alerts.jsonl" --out "$out/page.png"

echo
section "== twin control: LQR designed on the twin calibrated on dataset1 (paper section 6: q = 1e3, 5e3, R = 0.1), on dataset2 =="
"$twin" control --twin "$out/calibrated.ssp" --data data/dataset2.csv --q 1e3 --q 5e3 --r 0.1 \
  --estimator-costs --report "$out/control-dataset2.json" --plot "$out/control-dataset2.svg" \
  --ssp "$out/controlled-dataset2.ssp"

echo
section "== the controlled system (shear FMU + LQR FMU, q = 1e3) is an SSP any FMI master runs: twin run it =="
cut -d, -f1,2 data/dataset2.csv >"$out/force-dataset2.csv"
control_step=$(python3 -c "import json, sys; print(1 / json.load(open(sys.argv[1]))['control_rate_hz'])" "$out/control-dataset2.json")
"$twin" run "$out/controlled-dataset2.ssp" --algorithm jacobi --input "$out/force-dataset2.csv" \
  --step "$control_step" --stop 19.98046875 --output "$out/run-controlled-dataset2.csv"

echo
section "== twin control on dataset3, the structure with the contact add-physics found: contacts passive, fixed gains, scheduled =="
"$twin" control --twin "$out/with-contact.ssp" --data data/dataset3.csv --q 1e3 --q 5e3 --r 0.1 \
  --schedule --report "$out/control-dataset3.json" --plot "$out/control-dataset3.svg"

echo
section "== twin-informed control: from a light controller (q = 10) the retune finds the smallest q keeping the contacts at 3 or fewer; the schedule uses it only near the gap =="
"$twin" control --twin "$out/with-contact.ssp" --data data/dataset3.csv --q 10 --r 0.1 \
  --retune --schedule --report "$out/control-retune-dataset3.json" --plot "$out/control-retune-dataset3.svg"

echo
section "== gain scheduling on the twin's uncertainty: the twin with the GP corrector (no contact physics) switches to the high gain where the corrector is unsure =="
"$twin" control --twin "$out/corrected.ssp" --data data/dataset3.csv --q 10 --q 300 --r 0.1 \
  --schedule --gap 2-3:5e-4:negative --report "$out/control-corrected-dataset3.json"

echo
section "== the controlled structure: a synthetic record with the q = 1e3 controller in its loop, predicted by the twin in the closed loop =="
"$twin" synth --out "$out/synth-passive.csv" --seed 5
"$twin" calibrate --data "$out/synth-passive.csv" --out "$out/synth-calibrated.ssp" >/dev/null
"$twin" control --twin "$out/synth-calibrated.ssp" --data "$out/synth-passive.csv" --q 1e3 \
  --report "$out/synth-control.json" >/dev/null
"$twin" synth --out "$out/synth-controlled.csv" --seed 5 --controller "$out/synth-control.json"
echo "-- passive record, twin run open loop:"
"$twin" compare --twin "$out/synth-calibrated.ssp" --data "$out/synth-passive.csv"
echo "-- controlled record, twin in the closed loop with the same controller:"
"$twin" compare --twin "$out/synth-calibrated.ssp" --data "$out/synth-controlled.csv" \
  --controller "$out/synth-control.json"

echo
section "== for contrast: recalibrating on dataset3 instead biases the parameters =="
"$twin" calibrate --data data/dataset3.csv --out "$out/calibrated-dataset3.ssp" \
  --validate data/dataset1.csv data/dataset2.csv --report "$out/calibrate-dataset3.json"
echo
section "== a measured FRF as data: the Swansea three-storey rig (data/frf, BSD-3 licence beside it) =="
echo "-- the twin from its description (data/frf/nominal.json), calibrated on the measured FRF (dB of"
echo "   unknown reference: a gain offset is fitted), then drawn over it; twin frequencies beside the peaks --"
frf="$out/frf"
mkdir -p "$frf"
"$twin" init --nominal data/frf/nominal.json --out "$frf/drawings.ssp"
"$twin" calibrate --twin "$frf/drawings.ssp" --frf data/frf/swansea-3storey-frf.csv --band 3:40 --gain-offset \
  --out "$frf/calibrated.ssp" --report "$frf/calibrate.json" --plot "$frf/calibrate.svg"
"$twin" compare --twin "$frf/calibrated.ssp" --frf data/frf/swansea-3storey-frf.csv --band 3:40 --gain-offset \
  --report "$frf/compare.json" --plot "$frf/compare.svg"

echo
section "== from Python (shear_twin) and a fleet of synthetic structures on Dask =="
.venv/bin/python - "$out" <<'PY'
import sys
import shear_twin as st
out = sys.argv[1]
twin = st.Twin.open(f"{out}/calibrated.ssp")
record = st.Record.read("data/dataset3.csv")
diagnosis = twin.diagnose(record)
with_contact, added = twin.add_physics(record, diagnosis=diagnosis)
print(f"python: dataset3 {diagnosis.action} {diagnosis.effect['label']}: worst-floor NMSE "
      f"{max(added.nmse_before):.2f} % -> {max(with_contact.compare(record).nmse):.3f} %")
PY
"$twin" fleet synth --out "$out/fleet" --structures 4 --duration 10 --bad 1 >/dev/null
"$twin" fleet "$out/fleet/manifest.json" --workers 2 --out "$out/fleet/report"
echo
section "the demo is done: reports, predictions and plots are in $out/"
