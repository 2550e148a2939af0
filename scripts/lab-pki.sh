#!/usr/bin/env bash
# The lab's own certificate authority for `upc bridge` (services/BRIDGE_SECURITY.md), with
# openssl (Debian's `openssl`, installed by scripts/setup.sh).
#
#   scripts/lab-pki.sh ca DIR [NAME]          the CA: DIR/ca.pem (give it to every participant)
#                                             and DIR/ca.key (keep it offline)
#   scripts/lab-pki.sh issue DIR NAME [SAN…]  a participant's certificate DIR/NAME.pem and key
#                                             DIR/NAME.key, signed by DIR's CA. NAME is the
#                                             identity the bridge's access control lists.
#                                             SANs are the names clients connect to (the
#                                             bridge's host): DNS:robot.lab, IP:10.0.0.2.
#                                             Default: DNS:localhost,IP:127.0.0.1,IP:::1.
#
# Keys are ECDSA P-256 (what rustls, Zenoh's TLS, and Python's Zenoh accept). Certificates
# serve both as server and as client (a bridge may also connect out).
set -euo pipefail
die() { echo "lab-pki: $*" >&2; exit 2; }
command -v openssl >/dev/null 2>&1 || die "openssl not found (scripts/setup.sh installs it)"
[ $# -ge 2 ] || die "usage: $0 ca DIR [NAME] | $0 issue DIR NAME [SAN...]"
cmd=$1 dir=$2
shift 2
mkdir -p "$dir"
umask 077
key() { openssl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:P-256 -out "$1" 2>/dev/null; }
case "$cmd" in
  ca)
    name=${1:-upc lab CA}
    [ -e "$dir/ca.key" ] && die "$dir/ca.key exists: a CA is made once"
    key "$dir/ca.key"
    openssl req -x509 -new -key "$dir/ca.key" -sha256 -days 3650 -subj "/CN=$name" \
      -addext "basicConstraints=critical,CA:TRUE" \
      -addext "keyUsage=critical,keyCertSign,cRLSign" -out "$dir/ca.pem"
    chmod 644 "$dir/ca.pem"
    echo "CA \"$name\": $dir/ca.pem (public), $dir/ca.key (secret)"
    ;;
  issue)
    [ $# -ge 1 ] || die "issue: which NAME?"
    name=$1
    shift
    case "$name" in */*|*\**|*\$*|*\?*|*\#*|"") die "\`$name\`: an identity is one key chunk (no / * \$ ? #)";; esac
    [ -f "$dir/ca.key" ] || die "no CA in $dir (run: $0 ca $dir)"
    if [ $# -eq 0 ]; then set -- DNS:localhost IP:127.0.0.1 IP:::1; fi
    san=$(IFS=,; echo "$*")
    key "$dir/$name.key"
    ext=$(mktemp)
    trap 'rm -f "$ext" "$dir/$name.csr"' EXIT
    printf '%s\n' "basicConstraints=critical,CA:FALSE" "keyUsage=critical,digitalSignature" \
      "extendedKeyUsage=serverAuth,clientAuth" "subjectAltName=$san" >"$ext"
    openssl req -new -key "$dir/$name.key" -subj "/CN=$name" -out "$dir/$name.csr"
    openssl x509 -req -in "$dir/$name.csr" -CA "$dir/ca.pem" -CAkey "$dir/ca.key" \
      -set_serial "0x$(openssl rand -hex 16)" -days 825 -sha256 -extfile "$ext" \
      -out "$dir/$name.pem" 2>/dev/null
    chmod 644 "$dir/$name.pem"
    echo "$name: $dir/$name.pem, $dir/$name.key (SAN $san)"
    ;;
  *) die "unknown command \`$cmd\` (ca | issue)";;
esac
