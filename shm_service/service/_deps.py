from fastapi import Request
from contract import ServicePort
def service_port(request: Request) -> ServicePort:
    return request.app.state.port
