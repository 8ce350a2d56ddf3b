#!/usr/bin/env bash
# Makes a run's certificates and zenoh configurations for an authenticated run: a certificate
# authority of its own, one key and certificate per role whose common name is the role, and per role a
# zenoh config with mutual TLS and the access control that lets each role do only its part.
#
#   deploy/certs.sh DIR [HOST ...]
#
# DIR gets ca.pem (give it to every host), ca.key (keep it: it signs new members), and for each of
# learner, executor, replay, param and monitor: <role>.key, <role>.pem and <role>.json5. HOSTs (names or
# IPs) are added to every certificate's subject alternative names beside localhost and 127.0.0.1.
# Start each role with `--zenoh-config DIR/<role>.json5` and tls/ endpoints (`local.sh AUTH=1` does).
# Copy a role's three files (plus ca.pem) only to the hosts that run that role: holding a key is what
# makes a process that role.
#
# What the access control allows (every role's session enforces it on what it receives, so a forged
# message is dropped at the first honest peer it reaches):
#   - only the learner publishes weights to the param server, learner steps, priorities and evaluations,
#     and only it may query the replay server for samples;
#   - only executors publish experience, barrier reports and episodes;
#   - only the param server serves and announces weights and global steps;
#   - only the replay server answers sample queries and publishes durable marks;
#   - each role publishes only its own stats and liveliness tokens;
#   - the monitor (also `sac-lsp eval`/`monitor` from another host) only listens and queries weights;
#   - a peer whose certificate is not signed by ca.pem cannot connect, and one with another common
#     name is denied everything (default deny).
# Host names are not what is authenticated (the CA's signature and the role's common name are), so
# names are not verified on connect: endpoints may be plain IPs.
set -euo pipefail

dir=${1:?usage: deploy/certs.sh DIR [HOST ...]}
shift
command -v openssl >/dev/null || { echo "certs.sh: needs openssl" >&2; exit 2; }
mkdir -p "$dir"
dir=$(cd "$dir" && pwd)
roles=(learner executor replay param monitor)
days=${DAYS:-825}

san="DNS:localhost,IP:127.0.0.1"
for host in "$@"; do
    if [[ $host =~ ^[0-9.]+$ || $host == *:* ]]; then san+=",IP:$host"; else san+=",DNS:$host"; fi
done

# P-256 keys in PKCS#8, which rustls (zenoh's TLS) reads.
key() { openssl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:P-256 -out "$1" 2>/dev/null; chmod 600 "$1"; }

if [[ ! -f $dir/ca.pem ]]; then
    key "$dir/ca.key"
    openssl req -x509 -new -key "$dir/ca.key" -sha256 -days "$days" -subj "/CN=sac-lsp run CA" \
        -addext "basicConstraints=critical,CA:TRUE" -addext "keyUsage=critical,keyCertSign,cRLSign" \
        -out "$dir/ca.pem"
fi

ext=$(mktemp)
trap 'rm -f "$ext" "$dir"/*.csr' EXIT
for role in "${roles[@]}"; do
    key "$dir/$role.key"
    openssl req -new -key "$dir/$role.key" -subj "/CN=$role" -out "$dir/$role.csr"
    cat >"$ext" <<EOF
basicConstraints=critical,CA:FALSE
keyUsage=critical,digitalSignature
extendedKeyUsage=serverAuth,clientAuth
subjectAltName=$san
EOF
    openssl x509 -req -in "$dir/$role.csr" -CA "$dir/ca.pem" -CAkey "$dir/ca.key" -CAcreateserial \
        -days "$days" -sha256 -extfile "$ext" -out "$dir/$role.pem" 2>/dev/null
done

# Rule helpers: a JSON5 rule denying `messages` on `keys` (both lists already quoted).
deny() { # id, messages, keys
    echo "      { id: \"$1\", permission: \"deny\", flows: [\"ingress\"], messages: [$2], key_exprs: [$3] },"
}
pub='"put", "delete"'
serve='"declare_queryable", "reply"'
rules=$(
    echo '      { id: "members", permission: "allow", flows: ["ingress", "egress"], messages: ["put", "delete", "declare_subscriber", "query", "declare_queryable", "reply", "liveliness_token", "declare_liveliness_subscriber", "liveliness_query"], key_exprs: ["**"] },'
    deny learner-only "$pub" '"rl/*/params/publish", "rl/*/control/learner", "rl/*/replay/priorities", "rl/*/eval"'
    deny learner-samples '"query"' '"rl/*/replay/sample"'
    deny executor-only "$pub" '"rl/*/experience/*", "rl/*/control/barrier/*", "rl/*/episodes/*"'
    deny param-only "$pub" '"rl/*/params/weights", "rl/*/control/step"'
    deny param-serves "$serve" '"rl/*/params/weights", "rl/*/params/frozen"'
    deny replay-only "$pub" '"rl/*/replay/durable"'
    deny replay-serves "$serve" '"rl/*/replay/sample", "rl/*/replay/state"'
    deny monitor-listens "$pub, $serve, \"liveliness_token\"" '"**"'
    for role in learner executor replay param; do
        deny "own-$role" "$pub, \"liveliness_token\"" "\"rl/*/stats/$role/*\", \"rl/*/liveliness/$role/*\""
    done
)
# Who each deny rule binds: every role but the one it protects.
others() { # protected roles...
    local out=() r
    for r in learner executor replay param monitor; do
        [[ " $* " == *" $r "* ]] || out+=("\"$r\"")
    done
    local IFS=,
    echo "${out[*]}"
}
policy() { # rule, protected roles...
    local rule=$1
    shift
    echo "      { rules: [\"$rule\"], subjects: [$(others "$@")] },"
}
policies=$(
    echo '      { rules: ["members"], subjects: ["learner", "executor", "replay", "param", "monitor"] },'
    policy learner-only learner
    policy learner-samples learner
    policy executor-only executor
    policy param-only param
    policy param-serves param
    policy replay-only replay
    policy replay-serves replay
    policy monitor-listens learner executor replay param
    for role in learner executor replay param; do policy "own-$role" "$role"; done
)
subjects=$(for role in "${roles[@]}"; do echo "      { id: \"$role\", cert_common_names: [\"$role\"] },"; done)

for role in "${roles[@]}"; do
    cat >"$dir/$role.json5" <<EOF
// Made by deploy/certs.sh for role "$role"; use with tls/ endpoints.
{
  transport: {
    link: {
      tls: {
        root_ca_certificate: "$dir/ca.pem",
        listen_private_key: "$dir/$role.key",
        listen_certificate: "$dir/$role.pem",
        connect_private_key: "$dir/$role.key",
        connect_certificate: "$dir/$role.pem",
        enable_mtls: true,
        verify_name_on_connect: false,
      },
    },
  },
  access_control: {
    enabled: true,
    default_permission: "deny",
    rules: [
$rules
    ],
    subjects: [
$subjects
    ],
    policies: [
$policies
    ],
  },
}
EOF
done
echo "certs.sh: CA and certificates for ${roles[*]} in $dir (SAN $san)" >&2
