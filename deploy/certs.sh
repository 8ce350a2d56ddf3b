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
# What the access control allows (every role's zenoh peer enforces it on what it receives, so a forged
# message is dropped at the first honest peer it reaches), as proto's topic registry says:
#   - only the role that writes a topic may publish it or serve its queries (the learner: weights to
#     the param server, learner steps, priorities, evaluations; executors: experience, barrier reports,
#     episodes; the param server: global steps, weights and frozen levels; the replay server: samples,
#     state, cuts, durable marks), and only the learner may query the replay server for samples;
#   - each role publishes only its own stats and liveliness tokens;
#   - the monitor (also `sac-lsp eval`/`monitor` from another host) only listens and queries;
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

# The access control, generated from proto's topic registry (proto/src/registry.rs), which says who
# publishes or serves each topic; `cargo test -p proto --test registry` fails when this block drifts
# from it and SACLSP_BLESS=1 rewrites it.
# topics:begin
rules='
      { id: "members", permission: "allow", flows: ["ingress", "egress"], messages: ["put", "delete", "declare_subscriber", "query", "declare_queryable", "reply", "liveliness_token", "declare_liveliness_subscriber", "liveliness_query"], key_exprs: ["**"] },
      { id: "learner-publishes", permission: "deny", flows: ["ingress"], messages: ["put", "delete"], key_exprs: ["rl/*/replay/priorities", "rl/*/params/publish", "rl/*/control/learner", "rl/*/eval"] },
      { id: "learner-queries", permission: "deny", flows: ["ingress"], messages: ["query"], key_exprs: ["rl/*/replay/sample"] },
      { id: "executor-publishes", permission: "deny", flows: ["ingress"], messages: ["put", "delete"], key_exprs: ["rl/*/experience/*", "rl/*/control/barrier/*", "rl/*/episodes/*"] },
      { id: "replay-publishes", permission: "deny", flows: ["ingress"], messages: ["put", "delete"], key_exprs: ["rl/*/replay/durable"] },
      { id: "replay-serves", permission: "deny", flows: ["ingress"], messages: ["declare_queryable", "reply"], key_exprs: ["rl/*/replay/sample", "rl/*/replay/state", "rl/*/replay/cut"] },
      { id: "param-publishes", permission: "deny", flows: ["ingress"], messages: ["put", "delete"], key_exprs: ["rl/*/params/stream", "rl/*/control/step"] },
      { id: "param-serves", permission: "deny", flows: ["ingress"], messages: ["declare_queryable", "reply"], key_exprs: ["rl/*/params/weights", "rl/*/params/frozen"] },
      { id: "monitor-listens", permission: "deny", flows: ["ingress"], messages: ["put", "delete", "declare_queryable", "reply", "liveliness_token"], key_exprs: ["**"] },
      { id: "own-learner", permission: "deny", flows: ["ingress"], messages: ["put", "delete", "liveliness_token"], key_exprs: ["rl/*/stats/learner/*", "rl/*/liveliness/learner/*"] },
      { id: "own-executor", permission: "deny", flows: ["ingress"], messages: ["put", "delete", "liveliness_token"], key_exprs: ["rl/*/stats/executor/*", "rl/*/liveliness/executor/*"] },
      { id: "own-replay", permission: "deny", flows: ["ingress"], messages: ["put", "delete", "liveliness_token"], key_exprs: ["rl/*/stats/replay/*", "rl/*/liveliness/replay/*"] },
      { id: "own-param", permission: "deny", flows: ["ingress"], messages: ["put", "delete", "liveliness_token"], key_exprs: ["rl/*/stats/param/*", "rl/*/liveliness/param/*"] },
'
policies='
      { rules: ["members"], subjects: ["learner", "executor", "replay", "param", "monitor"] },
      { rules: ["learner-publishes"], subjects: ["executor", "replay", "param", "monitor"] },
      { rules: ["learner-queries"], subjects: ["executor", "replay", "param", "monitor"] },
      { rules: ["executor-publishes"], subjects: ["learner", "replay", "param", "monitor"] },
      { rules: ["replay-publishes"], subjects: ["learner", "executor", "param", "monitor"] },
      { rules: ["replay-serves"], subjects: ["learner", "executor", "param", "monitor"] },
      { rules: ["param-publishes"], subjects: ["learner", "executor", "replay", "monitor"] },
      { rules: ["param-serves"], subjects: ["learner", "executor", "replay", "monitor"] },
      { rules: ["monitor-listens"], subjects: ["monitor"] },
      { rules: ["own-learner"], subjects: ["executor", "replay", "param", "monitor"] },
      { rules: ["own-executor"], subjects: ["learner", "replay", "param", "monitor"] },
      { rules: ["own-replay"], subjects: ["learner", "executor", "param", "monitor"] },
      { rules: ["own-param"], subjects: ["learner", "executor", "replay", "monitor"] },
'
# topics:end
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
