// Transport settings shared by catgs-server and catgs-client (and the tests), kept in one
// table so that both ends cannot disagree: message-size limits and keepalive.
#pragma once

#include <grpcpp/grpcpp.h>

#include <cstddef>

namespace catgs::net {

/// Largest server message (one Frame). A 3840x2160 frame is 24.9 MB as raw RGB8, and PNG of
/// noisy content can come out slightly larger than raw; 64 MiB leaves room for both plus the
/// frame's metadata. The client's receive limit must be at least this.
inline constexpr int kMaxFrameMessageBytes = 64 * 1024 * 1024;
/// Largest client message. A frame request with a full 16-pose flight plan is about 1 KB and
/// an opening message smaller still; 1 MiB bounds what a misbehaving client can make the
/// server buffer per read.
inline constexpr int kMaxRequestMessageBytes = 1024 * 1024;

/// Keepalive. Remote UAV viewers sit behind NAT/LTE links that drop idle flows within
/// minutes, so both ends ping: the client every 20 s, the server every 30 s; a ping not
/// answered within 10 s closes the connection. The server must permit the client's pings:
/// its minimum ping interval (10 s) is below the client's 20 s, otherwise the server answers
/// with GOAWAY "too_many_pings".
inline constexpr int kServerKeepaliveTimeMs = 30'000;
inline constexpr int kClientKeepaliveTimeMs = 20'000;
inline constexpr int kKeepaliveTimeoutMs = 10'000;
inline constexpr int kServerMinPingIntervalMs = 10'000;
static_assert(kServerMinPingIntervalMs <= kClientKeepaliveTimeMs, "the server would reject the client's pings");

inline void apply_server_args(grpc::ServerBuilder& builder) {
    builder.SetMaxReceiveMessageSize(kMaxRequestMessageBytes);
    builder.SetMaxSendMessageSize(kMaxFrameMessageBytes);
    builder.AddChannelArgument(GRPC_ARG_KEEPALIVE_TIME_MS, kServerKeepaliveTimeMs);
    builder.AddChannelArgument(GRPC_ARG_KEEPALIVE_TIMEOUT_MS, kKeepaliveTimeoutMs);
    builder.AddChannelArgument(GRPC_ARG_KEEPALIVE_PERMIT_WITHOUT_CALLS, 1);
    builder.AddChannelArgument(GRPC_ARG_HTTP2_MIN_RECV_PING_INTERVAL_WITHOUT_DATA_MS, kServerMinPingIntervalMs);
    builder.AddChannelArgument(GRPC_ARG_HTTP2_MAX_PINGS_WITHOUT_DATA, 0);
}

inline grpc::ChannelArguments client_channel_args() {
    grpc::ChannelArguments args;
    args.SetMaxReceiveMessageSize(kMaxFrameMessageBytes);
    args.SetMaxSendMessageSize(kMaxRequestMessageBytes);
    args.SetInt(GRPC_ARG_KEEPALIVE_TIME_MS, kClientKeepaliveTimeMs);
    args.SetInt(GRPC_ARG_KEEPALIVE_TIMEOUT_MS, kKeepaliveTimeoutMs);
    args.SetInt(GRPC_ARG_KEEPALIVE_PERMIT_WITHOUT_CALLS, 1);
    args.SetInt(GRPC_ARG_HTTP2_MAX_PINGS_WITHOUT_DATA, 0);
    return args;
}

}  // namespace catgs::net
