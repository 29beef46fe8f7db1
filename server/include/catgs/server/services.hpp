// The gRPC services: RenderService (Stream, Render) and SceneService, on the callback API.
// Every method is registered raw (ByteBuffer in and out) and parses its own request, so that
// bytes that are not a valid message get INVALID_ARGUMENT naming the message type (see
// wire.hpp); the method names, and so reflection and clients, are those of catgs.proto.
#pragma once

#include "catgs/server/server_core.hpp"
#include "catgs/v1/catgs.grpc.pb.h"

namespace catgs::server {

using RenderServiceBase = v1::RenderService::WithRawCallbackMethod_Stream<
    v1::RenderService::WithRawCallbackMethod_Render<v1::RenderService::Service>>;
using SceneServiceBase = v1::SceneService::WithRawCallbackMethod_LoadScene<
    v1::SceneService::WithRawCallbackMethod_ListScenes<v1::SceneService::WithRawCallbackMethod_UnloadScene<
        v1::SceneService::WithRawCallbackMethod_GetScene<v1::SceneService::Service>>>>;

class RenderServiceImpl final : public RenderServiceBase {
public:
    explicit RenderServiceImpl(ServerCore& core) : core_(core) {}
    grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>* Stream(grpc::CallbackServerContext* context) override;
    grpc::ServerUnaryReactor* Render(grpc::CallbackServerContext* context, const grpc::ByteBuffer* request,
                                     grpc::ByteBuffer* response) override;

private:
    ServerCore& core_;
};

class SceneServiceImpl final : public SceneServiceBase {
public:
    explicit SceneServiceImpl(ServerCore& core) : core_(core) {}
    grpc::ServerUnaryReactor* LoadScene(grpc::CallbackServerContext* context, const grpc::ByteBuffer* request,
                                        grpc::ByteBuffer* response) override;
    grpc::ServerUnaryReactor* ListScenes(grpc::CallbackServerContext* context, const grpc::ByteBuffer* request,
                                         grpc::ByteBuffer* response) override;
    grpc::ServerUnaryReactor* UnloadScene(grpc::CallbackServerContext* context, const grpc::ByteBuffer* request,
                                          grpc::ByteBuffer* response) override;
    grpc::ServerUnaryReactor* GetScene(grpc::CallbackServerContext* context, const grpc::ByteBuffer* request,
                                       grpc::ByteBuffer* response) override;

private:
    void fill(const SceneSummary& summary, v1::SceneInfo* info) const;
    ServerCore& core_;
};

}  // namespace catgs::server
