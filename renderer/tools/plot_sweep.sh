#!/usr/bin/env bash
# Plots a catgs-bench --sweep CSV (--csv-out) as time per frame against PSNR, one point per
# configuration, with the Pareto front (no other configuration both faster and more accurate)
# drawn as a line. Needs gnuplot (Debian: gnuplot-nox). Usage:
#   renderer/tools/plot_sweep.sh sweep.csv plot.png ["title"]
set -euo pipefail
if [ $# -lt 2 ]; then
  echo "usage: $0 SWEEP.csv OUT.png [TITLE]" >&2
  exit 2
fi
csv=$1 out=$2 title=${3:-"catgs: time per frame against error"}
command -v gnuplot >/dev/null || { echo "plot_sweep: gnuplot is missing (apt-get install gnuplot-nox)" >&2; exit 1; }
[ -s "$csv" ] || { echo "plot_sweep: $csv is empty or missing" >&2; exit 1; }
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

# name, median ms, PSNR mean (columns 1, 3, 11 of the CSV). The quoted pipeline column may
# hold commas: it is blanked before splitting (portable to mawk, which lacks FPAT).
awk -F, 'NR > 1 { gsub(/"[^"]*"/, "x"); $0 = $0; print $1, $3, $11 }' "$csv" > "$work/points"
# Pareto front: by time ascending, keep a point when its PSNR beats every faster one.
sort -g -k2 "$work/points" | awk 'BEGIN { best = -1 } $3 > best { print; best = $3 }' > "$work/front"

gnuplot <<GNUPLOT
set terminal pngcairo size 1100,700 noenhanced
set output "$out"
set title "$title"
set xlabel "median time per frame (ms)"
set ylabel "mean PSNR against the reference (dB)"
set grid
set key bottom right
set offsets graph 0.05, graph 0.2, graph 0.05, graph 0.05
plot "$work/points" using 2:3 with points pt 7 ps 1.5 title "configuration", \
     "$work/points" using 2:3:1 with labels offset 1,0.8 left notitle, \
     "$work/front" using 2:3 with linespoints lw 2 pt 6 ps 2.2 title "Pareto front"
GNUPLOT
echo "plot_sweep: $(wc -l < "$work/points") configurations, $(wc -l < "$work/front") on the Pareto front -> $out"
