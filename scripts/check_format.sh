#!/usr/bin/env bash
# Every tracked C++ file is formatted with the repository's .clang-format (clang-format 14).
# Fix with: git ls-files '*.cpp' '*.hpp' '*.h' | xargs clang-format -i
set -euo pipefail
cd "$(dirname "$0")/.."
mapfile -t files < <(git ls-files '*.cpp' '*.hpp' '*.h')
if ! clang-format --dry-run --Werror "${files[@]}" 2>/tmp/hysar-format.$$; then
  echo "format: these files differ from .clang-format (run clang-format -i on them):"
  grep -oE '^[^:]+\.(cpp|hpp|h):' /tmp/hysar-format.$$ | sort -u | sed 's/:$//; s/^/  /'
  rm -f /tmp/hysar-format.$$
  exit 1
fi
rm -f /tmp/hysar-format.$$
echo "format: ${#files[@]} C++ files match .clang-format"
