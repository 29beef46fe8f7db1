// The global flags of catgs-client: which server, how to authenticate, how to reconnect.
#pragma once

#include <CLI/CLI.hpp>
#include <grpcpp/grpcpp.h>

#include <chrono>
#include <memory>
#include <string>

#include "stream_runner.hpp"

namespace catgs::client {

/// How long to wait for the first connection before giving up with kExitUnavailable.
inline constexpr auto kConnectTimeout = std::chrono::seconds(10);

struct Connection {
    std::string server = "localhost:50051";
    std::string token_file;
    std::string tls_ca;             ///< PEM CA: use TLS
    std::string tls_cert, tls_key;  ///< PEM client certificate and key (mTLS)
    bool tls = false;
    RetryPolicy retry;
    /// Sent as metadata x-catgs-session on every call: a front proxy (deploy/envoy*.yaml)
    /// routes calls with the same value to the same server, so a reconnecting viewer finds its
    /// scene warm there. Empty: a random id per run.
    std::string session_id;

    /// Adds the metadata every call carries: the bearer token and the session id.
    void add_metadata(grpc::ClientContext& context, const std::string& authorization) const;
    /// "Bearer <first line of --token-file>", or empty without a token file.
    std::string authorization() const;
    /// own_connection: a TCP connection of its own (load tests: one per stream, as separate
    /// viewers would have).
    std::shared_ptr<grpc::Channel> channel(bool own_connection = false) const;
};

/// The flags as given, before the checks of make_connection.
struct ConnectionFlags {
    Connection connection;
    int retries = RetryPolicy{}.retries;
    long backoff_ms = RetryPolicy{}.backoff.count(), max_backoff_ms = RetryPolicy{}.max_backoff.count();
};

void add_connection_flags(CLI::App& app, ConnectionFlags& flags);

/// Checks the retry and session flags and draws a session id when none was given; throws
/// catgs::Error naming the flag.
Connection make_connection(const ConnectionFlags& flags);

}  // namespace catgs::client
