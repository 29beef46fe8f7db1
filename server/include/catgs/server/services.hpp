// The gRPC services: RenderService (Stream, Render) and SceneService, on the callback API.
#pragma once

#include "catgs/server/server_core.hpp"
#include "catgs/v1/catgs.grpc.pb.h"

namespace catgs::server {

class RenderServiceImpl final : public v1::RenderService::CallbackService {
public:
    explicit RenderServiceImpl(ServerCore& core) : core_(core) {}
    grpc::ServerBidiReactor<v1::StreamRequest, v1::Frame>* Stream(grpc::CallbackServerContext* context) override;
    grpc::ServerUnaryReactor* Render(grpc::CallbackServerContext* context, const v1::RenderRequest* request,
                                     v1::Frame* response) override;

private:
    ServerCore& core_;
};

class SceneServiceImpl final : public v1::SceneService::CallbackService {
public:
    explicit SceneServiceImpl(ServerCore& core) : core_(core) {}
    grpc::ServerUnaryReactor* LoadScene(grpc::CallbackServerContext* context, const v1::LoadSceneRequest* request,
                                        v1::SceneInfo* response) override;
    grpc::ServerUnaryReactor* ListScenes(grpc::CallbackServerContext* context, const v1::ListScenesRequest* request,
                                         v1::ListScenesResponse* response) override;
    grpc::ServerUnaryReactor* UnloadScene(grpc::CallbackServerContext* context, const v1::UnloadSceneRequest* request,
                                          v1::UnloadSceneResponse* response) override;
    grpc::ServerUnaryReactor* GetScene(grpc::CallbackServerContext* context, const v1::GetSceneRequest* request,
                                       v1::SceneInfo* response) override;

private:
    void fill(const SceneSummary& summary, v1::SceneInfo* info) const;
    ServerCore& core_;
};

}  // namespace catgs::server
