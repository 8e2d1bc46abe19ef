#!/usr/bin/env bash
# Regenerate docs/results (the README's Results section): HOPE, its initial map and ZoomOut on the
# first 6 pairs of every shared data set, the ablations on the first 2 pairs of each 5-7k set;
# then the SHOT, WKS and HKS initial maps on the first 2 pairs (docs/results/descriptors).
# Needs the eval extra (pip install ".[eval]") and ../shared/data (or DATA=...). About an hour
# on 2 cores.
set -euo pipefail
cd "$(dirname "$0")/.."
DATA="${DATA:-${HOPE_DATA:-../shared/data}}"
HOPE_RS="${HOPE_RS:-hope-rs}"
rm -f docs/results/*.csv docs/results/*.md docs/results/*.png docs/results/descriptors/*
$HOPE_RS bench "$DATA" \
  --methods init,hope,zoomout,hope-nolmd,hope-fixedk,hope-k4,hope-k12,hope-rand25,hope-rand50,hope-rand75 \
  --max-pairs 6 --ablation-pairs 2 \
  --ablation-sets faust_reg,faust_r,tosca_r,tosca_nonisometric_r \
  --up tosca=z,tosca_r=z,tosca_nonisometric_r=z \
  --out docs/results
# The three descriptors' initial maps on the first 2 pairs of each set.
$HOPE_RS bench "$DATA" --methods init,init-wks,init-hks --max-pairs 2 --no-render \
  --out docs/results/descriptors
