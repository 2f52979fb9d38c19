#!/bin/bash
# The runs behind docs/bench/fewshot_*.json (docs/perception.md, "How many of your own frames: the few-shot curve").
# usage (from the repository root, the [train] extra installed):
#   AERIAL_MIRRORS=/path/to/mirrors AERIAL_DATA_OUT=$HOME/.cache/aerodaas/aerial \
#     python examples/training/prepare_aerial_data.py auair          # AU-AIR's 80-frame sample (CC BY-NC-SA 2.0)
#   [SPLITS=A] docs/bench/fewshot_runs.sh [PHASE...]  # phases: shipped uniform ranked seed1 machine extra (default all;
#                                                    # SPLITS=A and SPLITS=B side by side ran the two splits at once)
#   python docs/bench/fewshot_curve.py table    # the table of docs/perception.md
#   python docs/bench/fewshot_curve.py clean    # delete the throwaway weights and staged sets ($FEWSHOT_CACHE)
# Every run: one training thread under nice (a shared 2-core machine), the schedule of fewshot_curve.py's TRAIN
# (--epochs 2 --tiles-per-epoch 160 --val-tiles 32: 40 steps of 8 tiles) unless given after --, scored on the split's two test flights.
set -u
export OMP_NUM_THREADS=1
F="python docs/bench/fewshot_curve.py run"
phases=${*:-shipped uniform ranked seed1 machine extra}
for ph in $phases; do
  case $ph in
    shipped) for s in ${SPLITS:-A B}; do $F --split $s --n 0; done ;;
    uniform) for s in ${SPLITS:-A B}; do for n in 10 60 20 40; do $F --split $s --n $n --select uniform --seed 0; done; done ;;
    ranked) for s in ${SPLITS:-A B}; do for n in 10 20 40; do $F --split $s --n $n --select ranked --seed 0; done; done ;;
    seed1) for s in ${SPLITS:-A B}; do for n in 10 20 40 60; do $F --split $s --n $n --select uniform --seed 1; done
             for n in 10 20 40; do $F --split $s --n $n --select ranked --seed 1; done; done ;;
    machine) for s in ${SPLITS:-A B}; do $F --split $s --n 10 --select uniform --seed 0 --machine-boxed; done ;;
    extra) [ "${SPLITS:-A}" = B ] && continue  # data or capacity: a 4x longer schedule, and larger training tiles, on the whole pool
      $F --split A --n 60 --seed 0 --tag long -- --epochs 4 --tiles-per-epoch 320 --val-tiles 32
      $F --split A --n 60 --seed 0 --tag tile640 -- --epochs 2 --tiles-per-epoch 160 --val-tiles 32 --tile 640 ;;
    *) echo "unknown phase $ph" >&2; exit 2 ;;
  esac
done
echo done
