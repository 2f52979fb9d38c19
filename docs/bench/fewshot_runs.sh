#!/bin/bash
# The runs behind docs/bench/fewshot_*.json (docs/results/detection.md, "The few-shot curve").
# usage (from the repository root, the [train] extra installed):
#   AERIAL_MIRRORS=/path/to/mirrors AERIAL_DATA_OUT=$HOME/.cache/aerodaas/aerial \
#     python examples/training/prepare_aerial_data.py auair          # AU-AIR's 80-frame sample (CC BY-NC-SA 2.0)
#   docs/bench/fewshot_runs.sh & docs/bench/fewshot_runs.sh & docs/bench/fewshot_runs.sh   # three queues
#   python docs/bench/fewshot_curve.py table    # the table of docs/results/detection.md
#   python docs/bench/fewshot_curve.py clean    # delete the throwaway weights, staged sets and claims ($FEWSHOT_CACHE)
# The list below is in order of priority; each queue takes the next run no other queue has taken (a claim file in
# $FEWSHOT_CACHE/claims) and skips the ones whose report exists, so queues can run side by side and a stopped list
# resumes. Every run trains on one thread under nice (a shared 2-core machine) with fewshot_curve.py's TRAIN schedule
# (--epochs 2 --tiles-per-epoch 160 --val-tiles 32: 40 steps of 8 tiles) unless given after --, and is scored on
# its split's two held-out flights.
set -u
export OMP_NUM_THREADS=1
F="python docs/bench/fewshot_curve.py run"
for s in A B; do $F --split $s --n 0; done                                   # the shipped model
for n in 10 60; do for s in A B; do $F --split $s --n $n --select uniform --seed 0; done; done
for n in 10 20 40; do
  for s in A B; do $F --split $s --n $n --select ranked --seed 0; done
  [ $n = 10 ] && continue
  for s in A B; do $F --split $s --n $n --select uniform --seed 0; done
done
for s in A B; do $F --split $s --n 10 --select uniform --seed 1; done        # a second seed
$F --split A --n 10 --select uniform --seed 0 --machine-boxed                  # + the other 50 pool frames, machine-boxed
$F --split A --n 60 --seed 0 --tag long -- --epochs 4 --tiles-per-epoch 160 --val-tiles 32   # twice the steps
$F --split B --n 10 --select uniform --seed 0 --machine-boxed
for s in A B; do $F --split $s --n 60 --select uniform --seed 1; done
for s in A B; do $F --split $s --n 10 --select ranked --seed 1; done
$F --split A --n 60 --seed 0 --tag tile640 -- --epochs 2 --tiles-per-epoch 160 --val-tiles 32 --tile 640
for n in 20 40; do for sel in uniform ranked; do for s in A B; do $F --split $s --n $n --select $sel --seed 1; done
  done; done
# a schedule that fits better: 10 epochs (200 steps of 8 tiles), five times the default
L="--epochs 10 --tiles-per-epoch 160 --val-tiles 32"
for s in A B; do $F --split $s --n 60 --select uniform --seed 0 --tag fit200 -- $L; done
for sel in uniform ranked; do for s in A B; do $F --split $s --n 20 --select $sel --seed 0 --tag fit200 -- $L; done; done
$F --split A --n 60 --select uniform --seed 1 --tag fit200 -- $L
# fitting or data: three times fit200's steps (600 steps of 8 tiles) and fit200 on 640-pixel training tiles; the
# curve's missing N = 40
X="--epochs 30 --tiles-per-epoch 160 --val-tiles 32"
for s in A B; do $F --split $s --n 60 --select uniform --seed 0 --tag fit600 -- $X; done
$F --split A --n 60 --select uniform --seed 0 --tag tile640fit200 -- $L --tile 640
for s in A B; do $F --split $s --n 40 --select uniform --seed 0 --tag fit200 -- $L; done
echo done
