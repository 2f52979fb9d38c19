#!/bin/bash
# The runs behind docs/bench/detect46_*.json (docs/results/detection.md).
# usage (from the repository root): docs/bench/detect46_runs.sh tiles|sets|scale|selftrain|oblique2 OUTDIR  (aerial splits laid
# out by examples/training/prepare_aerial_data.py in $S; the shared photos in $AERODAAS_DATA_DIR/imagery/brighton_beach;
# for selftrain, MEVA's UAV montage in $MEVA and stage 4 of docs/results/detection.md in $R/v4/model.onnx)
set -u
S=${S:-/work/cache/aerial/splits}; O=$2; mkdir -p "$O"
B="aerodaas bench detect --names car large_vehicle person --repeat 1 --sweep --thresholds 0.2 0.3 0.4 --overlap 0.2"
J="--images $S/jekhor_test/images --annotations $S/jekhor_test/labels --classes car large_vehicle"
C="--images $S/cats_lab_eval_only/images --annotations $S/cats_lab_eval_only/labels --classes car --limit 100"
if [ "$1" = selftrain ]; then  # the self-training round (2026-11-28): candidates 5a-5d, each scored on three sets
  R=${R:-runs}; T="--data $S/jekhor_train --data $S/hit_uav_train --val $S/jekhor_val --val $S/hit_uav_val"
  T="$T --tiles-per-epoch 640 --val-tiles 200"
  for sc in 0.45 0.6; do  # stage 4 boxes the montage again (the shots kept for tests and the title left out)
    python3 examples/training/pseudo_label_video.py "$MEVA" "$O/meva_$sc" --model $R/v4/model.onnx --input 928x1600 \
      --score $sc --step 5 --skip 0:30 --skip 1087:1162 --skip 1464:1539
  done
  aerodaas train detector $T --data "$O/meva_0.45" --base-model $R/v4/model.onnx --epochs 10 --object-px 4 96 \
    --oblique 0.5 --seed 5 --out $R/5a
  aerodaas train detector $T --data "$O/meva_0.6" --base-model $R/v4/model.onnx --epochs 10 --object-px 4 96 \
    --oblique 0.5 --seed 5 --out $R/5b
  aerodaas train detector $T --data "$O/meva_0.6" --base-model aerodaas/perception/models/aerial_nano.onnx \
    --epochs 10 --oblique 0.5 --seed 6 --out $R/5c
  aerodaas train detector $T --data "$O/meva_0.6" --base-model $R/5b/model.onnx --epochs 4 --seed 7 --out $R/5d
  for c in 5a 5b 5c 5d; do
    E="$B --thresholds 0.2 0.25 0.3 0.4 --threads 2 --tiles 0 --input-sizes 736x1280 --model-path $R/$c/model.onnx"
    $E --images $S/jekhor_eval_only/images --annotations $S/jekhor_eval_only/labels --classes car \
      --out "$O/stage${c}_jekhor_eval_only.json" >/dev/null
    $E $J --out "$O/stage${c}_jekhor_test.json" >/dev/null
    $E --images $S/hit_uav_test/images --annotations $S/hit_uav_test/labels --classes car person \
      --frame-meta hit-uav --out "$O/stage${c}_hit_uav_test.json" >/dev/null
  done
elif [ "$1" = oblique2 ]; then  # two more evaluation-only oblique colour sets (2026-11-28): AU-AIR's sample, SAR persons
  for m in aerial_nano yolox_nano; do
    G=""; [ $m = yolox_nano ] && G="--group large_vehicle=truck,bus"
    E="$B --threads 2 --tiles 0 --model $m"
    $E $G --images $S/auair_eval_only/images --annotations $S/auair_eval_only/labels --classes car large_vehicle person \
      --out "$O/${m}_auair_eval_only.json" >/dev/null
    [ $m = yolox_nano ] && G="--group vehicle=car,large_vehicle,truck,bus" || G="--group vehicle=car,large_vehicle"
    $E $G --images $S/auair_eval_only/images --annotations $S/auair_eval_only/labels --classes vehicle \
      --out "$O/${m}_auair_eval_only_vehicle.json" >/dev/null
    $E --images $S/sar_persons_eval_only/images --annotations $S/sar_persons_eval_only/labels --classes person \
      --out "$O/${m}_sar_persons_eval_only.json" >/dev/null
  done
  # persons in colour with the COCO model the person apps use, tiled (640 px tiles + the whole frame, as the app could)
  $B --threads 2 --model yolox_nano --tiles 0 640 --images $S/sar_persons_eval_only/images \
    --annotations $S/sar_persons_eval_only/labels --classes person --out "$O/yolox_nano_sar_persons_tiles.json" >/dev/null
  aerodaas bench detect --names car large_vehicle person --repeat 1 --sweep --thresholds 0.1 0.15 0.2 0.3 --overlap 0.2 \
    --threads 2 --model yolox_nano --tiles 416 960 --images $S/sar_persons_eval_only/images \
    --annotations $S/sar_persons_eval_only/labels --classes person --out "$O/yolox_nano_sar_persons_tiles_416_960.json" >/dev/null
  R=${R:-runs}
  for c in v4 5b; do  # stage 4 and candidate 5b of the sections on oblique colour views
    $B --threads 2 --tiles 0 --input-sizes 736x1280 --model-path $R/$c/model.onnx --images $S/auair_eval_only/images \
      --annotations $S/auair_eval_only/labels --classes car large_vehicle person --out "$O/stage${c#v}_auair_eval_only.json" >/dev/null
  done
elif [ "$1" = scale ]; then  # the input scale on far oblique views, and its check on HIT-UAV by view angle (2026-11-27)
  for in in 736x1280 1088x1920 1440x2560; do
    $B --images $S/jekhor_eval_only/images --annotations $S/jekhor_eval_only/labels --classes car --model aerial_nano \
       --threads 1 --thresholds 0.1 0.15 0.2 0.25 0.3 --input-sizes $in --tiles 0 \
       --out "$O/scale_jekhor_eval_only_$in.json" >/dev/null
    $B --images $S/hit_uav_test/images --annotations $S/hit_uav_test/labels --classes car person --model aerial_nano \
       --threads 1 --thresholds 0.2 0.3 --frame-meta hit-uav --input-sizes $in --tiles 0 \
       --out "$O/scale_hit_uav_test_$in.json" >/dev/null
  done
elif [ "$1" = tiles ]; then  # whole frame vs tiles (+ the whole frame at the tile's input size), aerial_nano
  for set in jekhor_test cats_lab; do
    [ $set = jekhor_test ] && A=$J || A=$C
    $B $A --model aerial_nano --tiles 0 --out "$O/tiles_${set}_whole.json" >/dev/null
    for t in 416 640 960; do
      $B $A --model aerial_nano --input-sizes $t --tiles $t --out "$O/tiles_${set}_$t.json" >/dev/null
    done
  done
else  # every held-out split and evaluation-only set, aerial_nano and the COCO yolox_nano side by side, whole frame
  for m in aerial_nano yolox_nano; do
    G=""; [ $m = yolox_nano ] && G="--group large_vehicle=truck,bus"
    $B $J --model $m $G --out "$O/sets_${m}_jekhor_test.json" >/dev/null
    $B --images $S/hit_uav_test/images --annotations $S/hit_uav_test/labels --classes car person --model $m $G \
       --out "$O/sets_${m}_hit_uav_test.json" >/dev/null
    $B --images $S/jekhor_eval_only/images --annotations $S/jekhor_eval_only/labels --classes car --model $m $G \
       --out "$O/sets_${m}_jekhor_eval_only.json" >/dev/null
    $B --images $S/cats_lab_eval_only/images --annotations $S/cats_lab_eval_only/labels --classes car --limit 300 \
       --model $m $G --out "$O/sets_${m}_cats_lab_eval_only.json" >/dev/null
    $B --images $AERODAAS_DATA_DIR/imagery/brighton_beach --annotations tests/data/brighton_beach_cars.json \
       --classes car --model $m $G --out "$O/sets_${m}_brighton_beach.json" >/dev/null
  done
fi
echo done
