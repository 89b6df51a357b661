# Sourced by the app tests: refused "expected message" command... runs the command, which must fail
# and print the message (a grep pattern); the output goes to $work/out.log.
refused() {
  want="$1"; shift
  if "$@" > "$work/out.log" 2>&1; then echo "accepted: $*"; exit 1; fi
  grep -q -- "$want" "$work/out.log" || { echo "no '$want' for: $*"; cat "$work/out.log"; exit 1; }
}
