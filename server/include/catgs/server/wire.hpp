// Messages as bytes. Every catgs.v1 method is registered as a raw (ByteBuffer) callback
// method and parses its request itself: with generated typed handlers, gRPC 1.51 answers a
// request that is not valid protobuf with UNIMPLEMENTED and an empty message (unary), or
// reports it to a stream as an ordinary end of stream (OnReadDone(false)), which would make a
// corrupted pose look like a client half-close. Parsing here lets the server answer
// INVALID_ARGUMENT naming the message type instead.
#pragma once

#include <grpcpp/grpcpp.h>
#include <grpcpp/impl/codegen/proto_utils.h>

#include <string>

namespace catgs::server {

/// Parses `in` (left untouched) into `out`; false when the bytes are not a valid message.
template <typename Message>
bool parse_message(const grpc::ByteBuffer& in, Message* out) {
    grpc::ByteBuffer copy(in);  // Deserialize consumes its buffer; the copy shares the slices
    return grpc::SerializationTraits<Message>::Deserialize(&copy, out).ok();
}

/// Serializes `message` into `out` (replacing its contents).
template <typename Message>
void serialize_message(const Message& message, grpc::ByteBuffer* out) {
    bool own_buffer = false;
    out->Clear();  // the serializer writes into an empty buffer only
    grpc::SerializationTraits<Message>::Serialize(message, out, &own_buffer);
}

/// The status for bytes that are not a valid `type` message.
inline grpc::Status malformed_request(const std::string& type, const grpc::ByteBuffer& in) {
    return {grpc::StatusCode::INVALID_ARGUMENT, "request: " + std::to_string(in.Length()) +
                                                    " bytes that are not a valid catgs.v1." + type +
                                                    " message (malformed protobuf)"};
}

}  // namespace catgs::server
