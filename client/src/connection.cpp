#include "connection.hpp"

#include <cstdio>
#include <random>

#include "catgs/common/files.hpp"
#include "catgs/error.hpp"
#include "catgs/common/net_config.hpp"

namespace catgs::client {

void Connection::add_metadata(grpc::ClientContext& context, const std::string& authorization) const {
    if (!authorization.empty()) context.AddMetadata("authorization", authorization);
    if (!session_id.empty()) context.AddMetadata(kSessionHeader, session_id);
}

std::string Connection::authorization() const {
    if (token_file.empty()) return "";
    // The server reads its --token-file the same way: the same file gives the same token.
    return "Bearer " + read_token(token_file);
}

std::shared_ptr<grpc::Channel> Connection::channel(bool own_connection) const {
    std::shared_ptr<grpc::ChannelCredentials> creds = grpc::InsecureChannelCredentials();
    if (tls_cert.empty() != tls_key.empty()) throw Error("--tls-cert and --tls-key: give both or neither");
    if (tls || !tls_ca.empty() || !tls_cert.empty()) {
        grpc::SslCredentialsOptions ssl;
        if (!tls_ca.empty()) ssl.pem_root_certs = read_file(tls_ca, "--tls-ca");
        if (!tls_cert.empty()) {
            ssl.pem_cert_chain = read_file(tls_cert, "--tls-cert");
            ssl.pem_private_key = read_file(tls_key, "--tls-key");
        }
        creds = grpc::SslCredentials(ssl);
    }
    grpc::ChannelArguments args = net::client_channel_args();
    // The channel's own reconnection follows our backoff, so a restarted server is found
    // as soon as a retry asks for it.
    args.SetInt(GRPC_ARG_INITIAL_RECONNECT_BACKOFF_MS, static_cast<int>(retry.backoff.count()));
    args.SetInt(GRPC_ARG_MAX_RECONNECT_BACKOFF_MS, static_cast<int>(retry.max_backoff.count()));
    // gRPC reads this one as the least time a connection attempt gets to finish its handshake
    // (its "min connect timeout"), not as a backoff. Set to the backoff (250 ms) it abandoned
    // every attempt that needed longer: a TLS handshake over a slow link, or a loaded server
    // (a sanitizer run saw 24 attempts in a row fail "before receiving SETTINGS frame"). A
    // refused connection still fails at once, so a restarted server is found as quickly.
    args.SetInt(GRPC_ARG_MIN_RECONNECT_BACKOFF_MS,
                static_cast<int>(std::chrono::duration_cast<std::chrono::milliseconds>(kConnectTimeout).count()));
    if (own_connection) args.SetInt(GRPC_ARG_USE_LOCAL_SUBCHANNEL_POOL, 1);
    return grpc::CreateCustomChannel(server, creds, args);
}

void add_connection_flags(CLI::App& app, ConnectionFlags& flags) {
    Connection& conn = flags.connection;
    app.add_option("--server", conn.server, "server address host:port")->capture_default_str();
    app.add_option("--token-file", conn.token_file, "send 'authorization: Bearer <first line of the file>'");
    app.add_option("--session-id", conn.session_id,
                   "sent as metadata 'x-catgs-session' on every call, so that a front proxy sends a reconnecting "
                   "client back to the server that holds its scene warm (load: ID-N for stream N; default: random "
                   "per run)");
    app.add_flag("--tls", conn.tls, "connect with TLS (system roots unless --tls-ca)");
    app.add_option("--tls-ca", conn.tls_ca, "PEM CA bundle to verify the server (implies --tls)");
    app.add_option("--tls-cert", conn.tls_cert,
                   "PEM client certificate chain for mutual TLS (with --tls-key; implies --tls)");
    app.add_option("--tls-key", conn.tls_key, "PEM private key of --tls-cert");
    app.add_option("--retries", flags.retries,
                   "stream and load: on UNAVAILABLE (server down, restarting or draining) reconnect up to this many "
                   "times in a row, resuming the trajectory in a new session (0: fail at once)")
        ->capture_default_str();
    app.add_option("--backoff-ms", flags.backoff_ms,
                   "first reconnection delay; the n-th retry in a row waits a random time between half and all of "
                   "min(--max-backoff-ms, backoff * 2^(n-1))")
        ->capture_default_str();
    app.add_option("--max-backoff-ms", flags.max_backoff_ms, "longest reconnection delay")->capture_default_str();
    app.add_option("--retry-seed", conn.retry.seed, "seed of the backoff jitter (0: from the clock)");
}

Connection make_connection(const ConnectionFlags& flags) {
    if (flags.retries < 0 || flags.retries > 1000) throw Error("--retries: expected 0..1000");
    if (flags.backoff_ms < 1 || flags.max_backoff_ms < flags.backoff_ms || flags.max_backoff_ms > 600'000)
        throw Error("--backoff-ms/--max-backoff-ms: expected 1 <= backoff <= max backoff <= 600000");
    Connection conn = flags.connection;
    if (conn.session_id.empty()) {
        char id[17];
        std::snprintf(id, sizeof id, "%016llx",
                      static_cast<unsigned long long>(std::random_device{}()) << 32 ^
                          static_cast<unsigned long long>(std::random_device{}()));
        conn.session_id = id;
    } else if (!valid_session_id(conn.session_id)) {
        throw Error("--session-id: expected 1.." + std::to_string(kMaxSessionIdLength) +
                    " printable ASCII characters (an HTTP/2 header value)");
    }
    conn.retry.retries = flags.retries;
    conn.retry.backoff = std::chrono::milliseconds(flags.backoff_ms);
    conn.retry.max_backoff = std::chrono::milliseconds(flags.max_backoff_ms);
    return conn;
}

}  // namespace catgs::client
