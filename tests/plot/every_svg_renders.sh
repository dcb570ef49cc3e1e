#!/usr/bin/env bash
# Every kind of SVG the CLI writes (analyze --plot, reconcile --plots, thermoreg --plot,
# thermoreg sweep) from the real program: each must be well-formed XML, render with
# rsvg-convert (librsvg2-bin) to a non-empty PNG, and show no tick label with float noise.
# Exit 77 = skipped (CTest SKIP_RETURN_CODE) only when rsvg-convert is missing.
# Usage: every_svg_renders.sh MANIKIN [KEEP_DIR]  (KEEP_DIR: leave the SVGs and PNGs there)
set -euo pipefail
manikin="$1"
command -v rsvg-convert >/dev/null || { echo "SKIP: rsvg-convert is not installed (apt-get install librsvg2-bin)"; exit 77; }
if [ -n "${2:-}" ]; then
  dir="$2"; mkdir -p "$dir"
else
  dir=$(mktemp -d); trap 'rm -rf "$dir"' EXIT
fi

"$manikin" simulate-campaign --out "$dir/campaign" --replicates 2 --seed 7 \
  --effect humidity_buoyancy:gamma=146 >/dev/null
"$manikin" analyze "$dir/campaign" --plot "$dir/analyze.svg" --png "$dir/analyze-cli.png" >/dev/null
"$manikin" reconcile "$dir/campaign" --plots "$dir/reconcile" --simulations 200 >/dev/null
"$manikin" thermoreg --plot "$dir/fig4.svg" >/dev/null
"$manikin" thermoreg sweep --t-step 5 --rh-step 19 --out "$dir/sweep" >/dev/null

svgs=("$dir/analyze.svg" "$dir/reconcile/parity.svg" "$dir/reconcile/residual_vs_driver.svg"
      "$dir/reconcile/residual_body_map.svg" "$dir/reconcile/residual_vs_height.svg" "$dir/fig4.svg"
      "$dir/sweep/core_diff.svg" "$dir/sweep/skin_diff.svg")
fail=0
for svg in "${svgs[@]}"; do
  name=${svg#"$dir"/}
  before=$fail
  if [ ! -s "$svg" ]; then echo "FAIL: $name missing or empty"; fail=1; continue; fi
  if ! /usr/bin/python3 -c 'import xml.dom.minidom,sys; xml.dom.minidom.parse(sys.argv[1])' "$svg"; then
    echo "FAIL: $name is not well-formed XML"; fail=1
  fi
  png="${svg%.svg}.png"
  rm -f "$png"
  if ! rsvg-convert -o "$png" "$svg"; then echo "FAIL: rsvg-convert exited non-zero on $name"; fail=1; fi
  if [ ! -s "$png" ]; then echo "FAIL: $name rendered to an empty PNG"; fail=1; fi
  # Tick and label text: a number with 4+ decimals means float noise leaked through.
  if grep -Eo '<text[^>]*>-?[0-9]+\.[0-9]{4,}[^<]*</text>' "$svg"; then
    echo "FAIL: $name has a number with float noise in its text"; fail=1
  fi
  [ "$fail" = "$before" ] && echo "ok: $name"
done
[ -s "$dir/analyze-cli.png" ] || { echo "FAIL: manikin analyze --png wrote no PNG"; fail=1; }
grep -q 'class="colour-bar"' "$dir/sweep/core_diff.svg" || { echo "FAIL: core_diff.svg has no colour bar"; fail=1; }
grep -q 'W/m²' "$dir/reconcile/parity.svg" || { echo "FAIL: parity.svg has no unit on its axes"; fail=1; }
# The body map: front and back of the 35 zones, before and after the claim (humidity buoyancy here).
zones=$(grep -o '<title>[^<]*σ, mean of' "$dir/reconcile/residual_body_map.svg" | wc -l)
[ "$zones" = 70 ] || { echo "FAIL: residual_body_map.svg draws $zones zones with a value, not 35 before and 35 after"; fail=1; }
grep -q 'after: + humidity_buoyancy' "$dir/reconcile/residual_body_map.svg" || { echo "FAIL: the body map does not name the claim after"; fail=1; }
exit "$fail"
