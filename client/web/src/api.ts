// Unary calls through the server's HTTP endpoint (docs/web.md): POST /api/<service>/<method>
// with a binary protobuf body; errors carry grpc-status / grpc-message headers.
import { create, fromBinary, toBinary, DescMessage, MessageShape } from "@bufbuild/protobuf";
import {
  GetSceneRequestSchema, ListScenesRequestSchema, ListScenesResponseSchema, SceneInfo, SceneInfoSchema,
} from "../gen/catgs/v1/catgs_pb";

export class ApiError extends Error {
  constructor(readonly method: string, readonly grpcStatus: number, message: string) {
    super(`${method}: ${message}`);
  }
}

export async function unary<I extends DescMessage, O extends DescMessage>(
  base: string, method: string, input: I, request: MessageShape<I>, output: O, token: string | undefined,
): Promise<MessageShape<O>> {
  const headers: Record<string, string> = { "content-type": "application/x-protobuf" };
  if (token) headers.authorization = `Bearer ${token}`;
  let response: Response;
  try {
    response = await fetch(new URL(`/api/${method}`, base), {
      method: "POST", headers, body: toBinary(input, request) as Uint8Array<ArrayBuffer>,
    });
  } catch (error) {
    throw new ApiError(method, 14, `UNAVAILABLE: the server cannot be reached (${String(error)})`);
  }
  if (!response.ok) {
    const status = Number(response.headers.get("grpc-status") ?? "2");
    const text = (await response.text()).trim();
    throw new ApiError(method, status, text || `HTTP ${response.status} ${response.statusText}`);
  }
  return fromBinary(output, new Uint8Array(await response.arrayBuffer()));
}

export async function listScenes(base: string, token: string | undefined): Promise<SceneInfo[]> {
  const response = await unary(base, "catgs.v1.SceneService/ListScenes", ListScenesRequestSchema,
                               create(ListScenesRequestSchema), ListScenesResponseSchema, token);
  return response.scenes;
}

export async function getScene(base: string, sceneId: string, token: string | undefined): Promise<SceneInfo> {
  return unary(base, "catgs.v1.SceneService/GetScene", GetSceneRequestSchema,
               create(GetSceneRequestSchema, { sceneId }), SceneInfoSchema, token);
}
