#!/bin/sh
# Builds the LinuxCNC HAL component hexacomp.so (halcompile, LinuxCNC's uspace build) with the
# hexacomp C library (libhexacomp.a) linked in statically, so the module needs no other file at run time.
#
#   integrations/linuxcnc/build-component.sh                  # builds ./hexacomp.so
#   integrations/linuxcnc/build-component.sh --out DIR        # writes DIR/hexacomp.so
#   sudo integrations/linuxcnc/build-component.sh --install   # also copies it to LinuxCNC's modules
#   ... --client-lib PATH   # use this libhexacomp.a instead of building it (release)
#
# Needs halcompile (Debian: linuxcnc-uspace-dev) and cargo.
set -eu

here=$(cd "$(dirname "$0")" && pwd)
repo=$(cd "$here/../.." && pwd)
out=$(pwd)
install=no
client_lib=

while [ $# -gt 0 ]; do
    case "$1" in
        --out) out=$2; shift 2 ;;
        --install) install=yes; shift ;;
        --client-lib) client_lib=$2; shift 2 ;;
        -h|--help) sed -n '2,10p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
        *) echo "build-component.sh: unknown argument '$1' (see --help)" >&2; exit 2 ;;
    esac
done

command -v halcompile >/dev/null || {
    echo "build-component.sh: halcompile not found; install LinuxCNC's development package" \
         "(Debian: apt-get install linuxcnc-uspace-dev)" >&2
    exit 1
}

if [ -z "$client_lib" ]; then
    (cd "$repo" && cargo build --release --locked -p hexacomp-client-c)
    client_lib="${CARGO_TARGET_DIR:-$repo/target}/release/libhexacomp.a"
fi
[ -f "$client_lib" ] || { echo "build-component.sh: no client library at $client_lib" >&2; exit 1; }
client_lib=$(cd "$(dirname "$client_lib")" && pwd)/$(basename "$client_lib")

mkdir -p "$out"
out=$(cd "$out" && pwd)
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cp "$here/hexacomp.comp" "$repo/client-c/include/hexacomp.h" "$work/"

# halcompile's uspace Makefile puts LDFLAGS before the component's object file, so the archive
# members are pulled in by naming the entry points with -u; the module's version script keeps
# everything but the HAL exports local, so the Rust runtime inside cannot clash with other modules.
entry_points=""
for symbol in hexacomp_connect hexacomp_set_timeout hexacomp_compensate_joints \
              hexacomp_close hexacomp_error_message; do
    entry_points="$entry_points -Wl,-u,$symbol"
done
(cd "$work" && LDFLAGS="$entry_points $client_lib -lgcc_s -lutil -lrt -lpthread -lm -ldl" \
    halcompile --compile hexacomp.comp)
cp "$work/hexacomp.so" "$out/hexacomp.so"
echo "built $out/hexacomp.so"

if [ "$install" = yes ]; then
    modules=$(linuxcnc_var RTLIB_DIR 2>/dev/null || echo /usr/lib/linuxcnc/modules)
    cp "$out/hexacomp.so" "$modules/hexacomp.so"
    echo "installed $modules/hexacomp.so"
fi
