"""Security material of a deployment: certificates and keys for the zenoh TLS links."""
