// catgs-health-probe: one grpc.health.v1.Health/Check call, for the container image's
// HEALTHCHECK (docker, docker compose). Kubernetes does not need it: kubelet's built-in gRPC
// probe asks the same service.
//
//   catgs-health-probe [--addr HOST:PORT] [--service NAME] [--timeout-ms MS]
//
// Defaults: --addr 127.0.0.1:8081 (the image's --health-address), --service "" (the whole
// server), --timeout-ms 2000. Plaintext only: catgs-server's --health-address listener is
// plaintext on purpose (probes speak neither TLS nor tokens).
//
// Exit status: 0 when the answer is SERVING; 1 otherwise (NOT_SERVING, an unknown service,
// the server unreachable or too slow, bad arguments), with one line on stderr saying which.
// Docker reads 0 as healthy and 1 as unhealthy, and reserves 2, so nothing else is used.
//
// The health messages are three bytes of protobuf at most, so they are written and read here
// by hand through gRPC's generic stub: no generated code, no health.proto, nothing beyond
// libgrpc++ (which catgs-server already links, so deploy/bundle.sh carries no new library).
#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/grpcpp.h>

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

namespace {

constexpr int kHealthy = 0;
constexpr int kUnhealthy = 1;

const char* const kUsage =
    "usage: catgs-health-probe [--addr HOST:PORT] [--service NAME] [--timeout-ms MS]\n"
    "  asks grpc.health.v1.Health/Check over plaintext; exit 0 when SERVING, else 1\n"
    "  defaults: --addr 127.0.0.1:8081 --service '' --timeout-ms 2000\n";

// HealthCheckRequest { string service = 1; }
std::string encode_request(const std::string& service) {
    std::string out;
    if (service.empty()) return out;         // proto3: an empty string is not written
    out.push_back(static_cast<char>(0x0a));  // field 1, wire type 2 (length-delimited)
    std::uint64_t n = service.size();
    while (n >= 0x80) {
        out.push_back(static_cast<char>((n & 0x7f) | 0x80));
        n >>= 7;
    }
    out.push_back(static_cast<char>(n));
    return out + service;
}

bool read_varint(const std::string& in, std::size_t* pos, std::uint64_t* value) {
    *value = 0;
    for (int shift = 0; shift < 64 && *pos < in.size(); shift += 7) {
        const auto byte = static_cast<unsigned char>(in[(*pos)++]);
        *value |= static_cast<std::uint64_t>(byte & 0x7f) << shift;
        if (!(byte & 0x80)) return true;
    }
    return false;
}

// HealthCheckResponse { ServingStatus status = 1; }: UNKNOWN 0, SERVING 1, NOT_SERVING 2,
// SERVICE_UNKNOWN 3 (Watch only). Returns -1 for a malformed message.
long decode_status(const std::string& in) {
    long status = 0;  // proto3: an absent enum is its zero value
    std::size_t pos = 0;
    while (pos < in.size()) {
        std::uint64_t key = 0, value = 0;
        if (!read_varint(in, &pos, &key)) return -1;
        const auto field = key >> 3;
        switch (key & 7) {
            case 0:
                if (!read_varint(in, &pos, &value)) return -1;
                if (field == 1) status = static_cast<long>(value);
                break;
            case 1:
                pos += 8;
                break;
            case 2:
                if (!read_varint(in, &pos, &value) || value > in.size() - pos) return -1;
                pos += value;
                break;
            case 5:
                pos += 4;
                break;
            default:
                return -1;
        }
        if (pos > in.size()) return -1;
    }
    return status;
}

const char* status_name(long status) {
    switch (status) {
        case 0:
            return "UNKNOWN";
        case 1:
            return "SERVING";
        case 2:
            return "NOT_SERVING";
        case 3:
            return "SERVICE_UNKNOWN";
        default:
            return "an unknown status";
    }
}

}  // namespace

int main(int argc, char** argv) {
    std::string addr = "127.0.0.1:8081", service;
    long timeout_ms = 2000;
    for (int i = 1; i < argc; ++i) {
        const std::string arg = argv[i];
        if (arg == "-h" || arg == "--help") {
            std::fputs(kUsage, stdout);
            return kHealthy;
        }
        if ((arg == "--addr" || arg == "--service" || arg == "--timeout-ms") && i + 1 < argc) {
            const std::string value = argv[++i];
            if (arg == "--addr") addr = value;
            if (arg == "--service") service = value;
            if (arg == "--timeout-ms") {
                char* end = nullptr;
                timeout_ms = std::strtol(value.c_str(), &end, 10);
                if (value.empty() || *end != '\0' || timeout_ms < 1 || timeout_ms > 600000) {
                    std::fprintf(stderr, "catgs-health-probe: --timeout-ms '%s': expected 1..600000\n", value.c_str());
                    return kUnhealthy;
                }
            }
            continue;
        }
        std::fprintf(stderr, "catgs-health-probe: unexpected argument '%s'\n%s", arg.c_str(), kUsage);
        return kUnhealthy;
    }

    auto channel = grpc::CreateChannel(addr, grpc::InsecureChannelCredentials());
    grpc::GenericStub stub(channel);
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::milliseconds(timeout_ms));
    const std::string body = encode_request(service);
    grpc::Slice slice(body.data(), body.size());
    grpc::ByteBuffer request(&slice, 1);
    grpc::CompletionQueue cq;
    auto call = stub.PrepareUnaryCall(&context, "/grpc.health.v1.Health/Check", request, &cq);
    call->StartCall();
    grpc::ByteBuffer response;
    grpc::Status status;
    call->Finish(&response, &status, reinterpret_cast<void*>(1));
    void* tag = nullptr;
    bool ok = false;
    if (!cq.Next(&tag, &ok) || !ok) {
        std::fprintf(stderr, "catgs-health-probe: %s: the call did not complete\n", addr.c_str());
        return kUnhealthy;
    }
    cq.Shutdown();
    while (cq.Next(&tag, &ok)) {
    }
    if (!status.ok()) {
        std::fprintf(stderr, "catgs-health-probe: %s service '%s': %s (code %d)\n", addr.c_str(), service.c_str(),
                     status.error_message().c_str(), static_cast<int>(status.error_code()));
        return kUnhealthy;
    }
    std::vector<grpc::Slice> slices;
    std::string bytes;
    if (response.Dump(&slices).ok())
        for (const auto& s : slices) bytes.append(reinterpret_cast<const char*>(s.begin()), s.size());
    const long serving = decode_status(bytes);
    if (serving != 1) {
        std::fprintf(stderr, "catgs-health-probe: %s service '%s': %s\n", addr.c_str(), service.c_str(),
                     serving < 0 ? "malformed response" : status_name(serving));
        return kUnhealthy;
    }
    std::printf("%s service '%s': SERVING\n", addr.c_str(), service.c_str());
    return kHealthy;
}
