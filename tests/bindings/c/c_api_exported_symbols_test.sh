#!/usr/bin/env bash
# libfastslam.so defines exactly the functions fastslam.h declares, and no other symbol (the
# engine inside it stays hidden).
#
# usage: c_api_exported_symbols_test.sh LIBRARY HEADER
set -euo pipefail
library=$1
header=$2
exported=$(nm -D --defined-only "$library" | awk '{print $3}' | sort)
declared=$(grep -o 'FASTSLAM_API [^(]*(' "$header" | grep -o 'fastslam_[a-z_]*(' | tr -d '(' | sort)
if [ "$exported" != "$declared" ]; then
  echo "FAILED: the exported symbols differ from the declared functions" >&2
  diff <(echo "$declared") <(echo "$exported") >&2 || true
  exit 1
fi
echo "$(echo "$exported" | wc -l) symbols exported, all declared in fastslam.h"
